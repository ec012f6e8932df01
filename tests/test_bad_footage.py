"""Footage that does not fit together: a camera's video shorter than the others, frame rates that
differ, an empty video, a frame range outside the footage. Each ends in one line naming the camera
and the fix; the command line exits 2 without a traceback."""
import cv2
import numpy as np
import pytest

from capture_variants import copy_capture, rewrite_video
from scene_helpers import scene_dir
from markerless_mocap.core.capture.capture import CaptureError, load_capture
from markerless_mocap.core.capture.frames import FrameSource, FrameSourceError

W, H = 64, 48


def _video(path, n, fps=25.0):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (W, H))
    for i in range(n):
        writer.write(np.full((H, W, 3), 4 * i % 255, np.uint8))
    writer.release()
    return path


@pytest.fixture
def uneven(tmp_path):
    return {"a": _video(tmp_path / "a.mp4", 41), "b": _video(tmp_path / "b.mp4", 21),
            "c": _video(tmp_path / "c.mp4", 41)}


def test_a_range_past_a_short_video_is_refused_naming_the_camera(uneven):
    with FrameSource(uneven) as src:
        assert src.require_frames(range(0, 21)) == list(range(21))
        with pytest.raises(FrameSourceError) as err:
            src.require_frames(range(0, 41))
    message = str(err.value)
    assert "camera 'b' (b.mp4) has only 21 frames (0-20)" in message
    assert "track frames 0-20 at most" in message and "full recording" in message
    assert "\n" not in message


def test_without_a_range_the_shared_frames_are_named_in_one_line(uneven):
    with FrameSource(uneven) as src:
        assert src.n_frames == 21 and src.frames_per_camera == {"a": 41, "b": 21, "c": 41}
        note = src.shorter_footage_note()
    assert note.startswith("'b' (b.mp4) has 21 frames, the other cameras up to 41") and "0-20" in note
    with FrameSource({"a": uneven["a"], "c": uneven["c"]}) as src:
        assert src.shorter_footage_note() is None


def test_a_range_outside_all_footage_is_refused(uneven):
    with FrameSource({"a": uneven["a"]}) as src:
        with pytest.raises(FrameSourceError, match=r"frames 50-60 asked for, but the capture has 41 frames \(0-40\)"):
            src.require_frames(range(50, 61))
        with pytest.raises(FrameSourceError, match="count from 0"):
            src.require_frames([-3, -2])


def test_frame_rates_that_differ_are_refused_naming_both(tmp_path):
    paths = {"slow": _video(tmp_path / "slow.mp4", 10, fps=25.0), "fast": _video(tmp_path / "fast.mp4", 10, fps=30.0)}
    with pytest.raises(FrameSourceError) as err:
        FrameSource(paths)
    assert "camera 'slow' runs at 25 fps but camera 'fast' at 30 fps" in str(err.value)
    assert "one frame rate" in str(err.value)
    with FrameSource(paths, fps=25.0) as src:  # a rate the caller states overrides the files
        assert src.fps == 25.0


def test_an_empty_video_is_refused_naming_the_camera(tmp_path):
    empty = _video(tmp_path / "empty.mp4", 0)
    with pytest.raises(FrameSourceError, match="camera 'empty'") as err:
        FrameSource({"ok": _video(tmp_path / "ok.mp4", 5), "empty": empty})
    assert "\n" not in str(err.value)


def test_load_capture_reports_differing_rates_as_a_capture_error(tmp_path):
    cap_dir = copy_capture(tmp_path / "walk")
    rewrite_video(cap_dir / "videos" / "cam3.mp4", keep=12, fps=25.0)
    with pytest.raises(CaptureError, match="camera 'cam3' runs at 25 fps but camera '.*' at 30 fps"):
        load_capture(cap_dir)


# ---- the command line (bpy): refusal before any tracking, the one-line warning without --frames
bpy_needed = pytest.mark.bpy


@pytest.fixture(scope="module")
def short_cam2(tmp_path_factory):
    pytest.importorskip("bpy")
    cap_dir = copy_capture(tmp_path_factory.mktemp("short") / "walk")
    assert rewrite_video(cap_dir / "videos" / "cam2.mp4", keep=20) == 20
    return cap_dir


def _track(capture, out, *extra):
    from markerless_mocap.operators.cli import main

    return main(["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(capture),
                 "--out", str(out), "--no-export", "--no-overlays", *extra])


@bpy_needed
def test_track_refuses_frames_past_a_short_video(short_cam2, tmp_path, capsys):
    assert _track(short_cam2, tmp_path / "out", "--frames", "0-40") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert "camera 'cam2' (cam2.mp4) has only 20 frames (0-19)" in err and "track frames 0-19 at most" in err
    assert not (tmp_path / "out" / "poses.npz").exists()


@bpy_needed
def test_track_without_frames_warns_once_and_takes_the_shared_range(short_cam2, tmp_path):
    import bpy

    from markerless_mocap.addon.scene_bridge import find_armature
    from markerless_mocap.operators.track_session import TrackSession

    bpy.ops.wm.open_mainfile(filepath=str(scene_dir("walk") / "subject.blend"))
    said = []
    session = TrackSession(bpy.context.scene, find_armature(bpy.context.scene), short_cam2, tmp_path / "out",
                           log=said.append)
    try:
        assert session.n_total == 20 and session.all_frames == list(range(20))
        warnings = [m for m in said if m.startswith("warning:")]
        assert warnings == ["warning: 'cam2' (cam2.mp4) has 20 frames, the other cameras up to 60: only the 20 "
                            "frames every camera covers (0-19) are tracked"]
    finally:
        session.capture.close()
