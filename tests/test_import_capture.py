"""Import Capture: a synthetic capture folder (2 calibrated cameras, 10-frame videos) -> Blender cameras.

The cameras read back from Blender must equal the calibrated ones, each must show its video as a
movie-clip background, and the scene must take the video's frame rate and length. Broken captures
must be refused with a message naming the camera, leaving the scene untouched.
"""
import importlib

import numpy as np
import pytest

pytestmark = pytest.mark.bpy

W, H, N_FRAMES, FPS = 160, 120, 10, 25


def _look_at(center, target, up=(0.0, 0.0, 1.0)):
    """World->camera rotation of a camera at `center` looking at `target` (OpenCV axes: y down, z forward)."""
    z = np.asarray(target, float) - center
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _cameras():
    from markerless_mocap.core.capture.camera import Camera

    cams = []
    for name, center, f, cx, cy, dist in (
            ("cam1", (3.0, -2.0, 1.6), 150.0, 81.3, 58.7, np.zeros(5)),
            ("cam2", (-2.5, -3.0, 2.2), 180.0, 77.0, 61.5, np.array([0.01, -0.002, 0.0, 0.0, 0.0]))):
        center = np.array(center)
        R = _look_at(center, (0.0, 0.0, 1.0))
        cams.append(Camera(name, [[f, 0, cx], [0, f, cy], [0, 0, 1]], dist, R, -R @ center, W, H))
    return cams


def _write_video(path, n_frames=N_FRAMES, size=(W, H), fps=FPS):
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    assert writer.isOpened()
    for i in range(n_frames):
        img = np.full((size[1], size[0], 3), 20 * i, np.uint8)
        cv2.putText(img, str(i), (10, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
        writer.write(img)
    writer.release()


@pytest.fixture
def capture_dir(tmp_path):
    from markerless_mocap.core.capture.calibration import write_toml_calibration

    cams = _cameras()
    write_toml_calibration(cams, tmp_path / "calibration.toml")
    for cam in cams:
        _write_video(tmp_path / "videos" / f"{cam.name}.mp4")
    return tmp_path


def _op_module(addon_module_name):
    return importlib.import_module(f"{addon_module_name}.operators.import_capture")


def _mocap_cameras(bpy):
    coll = bpy.data.collections.get("Mocap Cameras")
    return sorted((o for o in coll.objects if o.type == "CAMERA"), key=lambda o: o.name) if coll else []


def test_import_creates_calibrated_cameras_with_video_backgrounds(addon_module_name, bpy_module, capture_dir):
    bpy = bpy_module
    bridge = importlib.import_module(f"{addon_module_name}.addon.camera_bridge")
    scene = bpy.context.scene
    scene.frame_start = 5
    assert bpy.ops.mocap.import_capture(directory=str(capture_dir)) == {"FINISHED"}

    objs = _mocap_cameras(bpy)
    assert [o.name for o in objs] == ["cam1", "cam2"]
    for cam, obj in zip(_cameras(), objs):
        back = bridge.camera_from_object(obj, scene)
        np.testing.assert_allclose(back.K, cam.K, atol=1e-3)
        np.testing.assert_allclose(back.R, cam.R, atol=1e-6)
        np.testing.assert_allclose(back.center, cam.center, atol=1e-6)
        assert back.size == (W, H)
        np.testing.assert_allclose(obj["mocap_distortion"], cam.dist, atol=1e-12)

        assert obj.data.show_background_images
        (bg,) = obj.data.background_images
        assert bg.source == "MOVIE_CLIP"
        assert bpy.path.basename(bg.clip.filepath) == f"{cam.name}.mp4"
        assert bg.clip.frame_duration == N_FRAMES
        assert tuple(bg.clip.size) == (W, H)
        assert bg.clip.frame_start == 5  # capture frame 0 plays at the scene's first frame

    assert scene.render.fps == FPS and scene.render.fps_base == pytest.approx(1.0)
    assert (scene.frame_start, scene.frame_end) == (5, 5 + N_FRAMES - 1)
    assert scene.camera == objs[0]
    props = scene.mocap
    assert (props.camera_count, props.capture_frames) == (2, N_FRAMES)
    assert (props.frame_start, props.frame_end) == (0, N_FRAMES - 1)


def test_reimport_replaces_the_cameras(addon_module_name, bpy_module, capture_dir):
    bpy = bpy_module
    bpy.context.scene.mocap.capture_dir = str(capture_dir)
    for _ in range(2):
        assert bpy.ops.mocap.import_capture() == {"FINISHED"}
    assert [o.name for o in _mocap_cameras(bpy)] == ["cam1", "cam2"]
    assert len([c for c in bpy.data.cameras if c.users]) == 2
    assert len(bpy.data.movieclips) == 2  # clips are reused, not loaded again


def test_missing_video_is_refused_naming_the_camera(addon_module_name, bpy_module, capture_dir):
    bpy = bpy_module
    (capture_dir / "videos" / "cam2.mp4").unlink()
    with pytest.raises(FileNotFoundError, match=r"camera 'cam2'.*cam2\.mp4"):
        _op_module(addon_module_name).import_capture(bpy.context, capture_dir)
    # The operator turns the same error into a report (bpy raises it as RuntimeError for scripts).
    with pytest.raises(RuntimeError, match="cam2"):
        bpy.ops.mocap.import_capture(directory=str(capture_dir))
    assert _mocap_cameras(bpy) == []
    assert len(bpy.data.movieclips) == 0


def test_calibration_size_mismatch_is_refused(addon_module_name, bpy_module, capture_dir):
    bpy = bpy_module
    _write_video(capture_dir / "videos" / "cam1.mp4", size=(2 * W, 2 * H))
    with pytest.raises(ValueError, match=r"camera 'cam1'.*160x120.*320x240.*resized by 2"):
        _op_module(addon_module_name).import_capture(bpy.context, capture_dir)
    assert _mocap_cameras(bpy) == []


def test_no_capture_folder_names_the_fix(addon_module_name, bpy_module):
    with pytest.raises(RuntimeError, match="Capture panel"):
        bpy_module.ops.mocap.import_capture()


def test_fractional_frame_rate(addon_module_name, bpy_module):
    scene = bpy_module.context.scene
    _op_module(addon_module_name).set_scene_fps(scene, 29.97)
    assert scene.render.fps == 30
    assert scene.render.fps / scene.render.fps_base == pytest.approx(29.97, abs=1e-6)
