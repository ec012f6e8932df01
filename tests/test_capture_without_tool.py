"""tools/capture_without.py: a capture copied without some of its cameras loads with the others, their
calibration and footage unchanged; a camera it does not have, or fewer than two left, is a clear error."""
import numpy as np
import pytest
from scene_helpers import scene_dir
from tool_helpers import load_tool

from markerless_mocap.core.capture.calibration import CalibrationError
from markerless_mocap.core.capture.capture import load_capture


def test_a_capture_without_one_camera_keeps_the_others_as_they_were(tmp_path):
    tool = load_tool("capture_without")
    source = scene_dir("crossing_alone")
    kept = tool.capture_without(source, tmp_path / "three", ["cam1"])
    assert kept == ["cam2", "cam3", "cam4"]
    before, after = load_capture(source), load_capture(tmp_path / "three")
    try:
        assert after.camera_names == kept
        for name in kept:
            a, b = before.camera(name), after.camera(name)
            assert np.allclose(a.K, b.K) and np.allclose(a.R, b.R, atol=1e-12) and np.allclose(a.t, b.t, atol=1e-12)
        assert np.array_equal(before.frames.read_camera("cam3", 5), after.frames.read_camera("cam3", 5))
    finally:
        before.close()
        after.close()
    # the TOML's own lines, cam1's table left out: the numbers as written, not read and written again
    written = (tmp_path / "three" / "calibration.toml").read_text().splitlines()
    assert set(written) <= set((source / "calibration.toml").read_text().splitlines()) and '"cam1"' not in str(written)
    left = {p.relative_to(tmp_path / "three").as_posix() for p in (tmp_path / "three").rglob("*")}
    assert "videos/cam2.mp4" in left and "gt_joints.npz" in left and "subject.blend" in left
    assert not [p for p in left if "cam1" in p]


def test_a_camera_it_does_not_have_or_one_camera_left_is_refused(tmp_path):
    tool = load_tool("capture_without")
    source = scene_dir("crossing_alone")
    with pytest.raises(SystemExit, match="no camera named cam9; its cameras are cam1, cam2, cam3, cam4"):
        tool.capture_without(source, tmp_path / "a", ["cam9"])
    with pytest.raises(CalibrationError, match="at least two"):
        tool.capture_without(source, tmp_path / "b", ["cam1", "cam2", "cam3"])
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
