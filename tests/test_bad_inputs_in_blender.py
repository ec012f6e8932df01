"""The same bad inputs through the operators in Blender: Import refuses a broken capture and Check Rig
a broken rig with the one-line message the command line prints (bpy raises an operator's ERROR report
as RuntimeError for scripts), and Track refuses a frame range past a short video before it starts."""
import pytest

from capture_variants import copy_capture, rewrite_video
from rig_helpers import load_subject

pytestmark = pytest.mark.bpy


@pytest.mark.parametrize("breakage,message", [
    ("one_camera", r"calibration\.toml: one camera \('cam1'\) found; multi-camera tracking needs at least two"),
    ("nan", r"camera 'cam1' has NaN or infinite values in 'translation'; .*recalibrate"),
    ("fps", r"camera 'cam3' runs at 25 fps but camera 'cam4' at 30 fps; .*one frame rate"),
])
def test_import_refuses_a_broken_capture(addon_module_name, bpy_module, tmp_path, breakage, message):
    folder = copy_capture(tmp_path / "walk")
    calibration = folder / "calibration.toml"
    if breakage == "one_camera":
        calibration.write_text(calibration.read_text().split("[cam_1]")[0])
    elif breakage == "nan":
        calibration.write_text(calibration.read_text().replace("translation = [-0.014575982988923597,",
                                                               "translation = [nan,", 1))
    else:
        rewrite_video(folder / "videos" / "cam3.mp4", keep=10, fps=25.0)
    bpy = bpy_module
    bpy.context.scene.mocap.capture_dir = str(folder)
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.mocap.import_capture()
    assert not [o for o in bpy.context.scene.objects if o.type == "CAMERA"]


def test_check_rig_refuses_a_rig_100x_too_large_and_a_mesh_without_weights(addon_module_name, bpy_module):
    bpy = bpy_module
    arm, mesh = load_subject(bpy)
    arm.scale = (100.0,) * 3
    bpy.context.view_layer.update()
    with pytest.raises(RuntimeError, match=r"stands \d+ m tall .*too large for a person .*Ctrl\+A > Scale"):
        bpy.ops.mocap.check_subject()
    assert "too large" in bpy.context.scene.mocap.subject_problems
    arm, mesh = load_subject(bpy)
    for group in mesh.vertex_groups:
        group.remove(list(range(len(mesh.data.vertices))))
    with pytest.raises(RuntimeError, match="vertices carry no weight .*With Automatic Weights"):
        bpy.ops.mocap.check_subject()


def test_track_refuses_frames_past_a_short_video(addon_module_name, bpy_module, tmp_path):
    folder = copy_capture(tmp_path / "walk")
    rewrite_video(folder / "videos" / "cam2.mp4", keep=20)
    bpy = bpy_module
    load_subject(bpy)
    m = bpy.context.scene.mocap
    m.capture_dir, m.output_dir = str(folder), str(tmp_path / "out")
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 40
    with pytest.raises(RuntimeError, match=r"camera 'cam2' \(cam2\.mp4\) has only 20 frames \(0-19\)"):
        bpy.ops.mocap.track()
    assert not m.is_tracking and "track frames 0-19 at most" in m.last_error
