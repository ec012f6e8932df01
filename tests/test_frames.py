"""FrameSource: frame-exact random access in videos and image folders, offsets, cache, errors."""
import re

import cv2
import numpy as np
import pytest

from markerless_mocap.core.capture.frames import FrameSource, FrameSourceError, VideoNotFoundError, find_video

W, H = 160, 120


def make_frames(n, seed=0):
    """Frames that differ clearly: the frame number written large, and a bar that moves 3 px per frame."""
    rng = np.random.default_rng(seed)
    base = rng.integers(40, 80, size=3)
    frames = []
    for i in range(n):
        img = np.full((H, W, 3), base, np.uint8)
        cv2.rectangle(img, (3 * i % W, 0), (3 * i % W + 6, H - 1), (255, 255, 255), -1)
        cv2.putText(img, str(i), (30, 85), cv2.FONT_HERSHEY_SIMPLEX, 2.0, (0, 0, 255), 4)
        frames.append(img)
    return frames


def write_video(path, frames, fps=25.0):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (W, H))
    assert writer.isOpened()
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def write_folder(folder, frames, start=1):
    folder.mkdir(parents=True)
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{i + start:06d}.png"), f)
    return folder


def identify(image, frames):
    """(index of the written frame the image is closest to, mean abs diff to it)."""
    diffs = [np.abs(image.astype(np.int16) - f).mean() for f in frames]
    return int(np.argmin(diffs)), float(min(diffs))


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    frames = make_frames(40)
    path = write_video(tmp_path_factory.mktemp("v") / "cam_a.mp4", frames)
    return path, frames


def test_video_random_access_is_frame_exact(clip):
    path, frames = clip
    with FrameSource({"cam_a": path}, cache_size=0) as src:
        assert src.n_frames == 40 and src.fps == pytest.approx(25.0)
        assert src.image_size("cam_a") == (W, H)
        order = list(np.random.default_rng(1).permutation(40)) + [5, 6, 7, 8, 30, 31, 39, 0, 12]
        for f in order:
            img = src.read(int(f))["cam_a"]
            assert img.dtype == np.uint8 and img.shape == (H, W, 3)
            got, err = identify(img, frames)
            assert got == f and err < 6.0, (f, got, err)


def test_sequential_reads_do_not_seek(clip):
    path, frames = clip
    src = FrameSource({"cam_a": path}, cache_size=0)
    reader = src._readers["cam_a"]
    for f in range(20, 30):
        assert identify(src.read(f)["cam_a"], frames)[0] == f
    assert reader.seeks == 1  # only the jump to frame 20
    assert identify(src.read(35)["cam_a"], frames)[0] == 35  # small forward jump: grab, no seek
    assert reader.seeks == 1
    src.read(3)
    assert reader.seeks == 2
    src.close()


def test_cache_is_bounded_lru(clip):
    path, _ = clip
    src = FrameSource({"cam_a": path}, cache_size=3)
    reader = src._readers["cam_a"]
    a = src.read(20)["cam_a"]
    src.read(21), src.read(22)
    assert src.read(20)["cam_a"] is a  # cached
    src.read(23)  # evicts 21, the least recently used
    assert list(src._caches["cam_a"]) == [22, 20, 23]
    seeks = reader.seeks
    src.read(2)
    assert reader.seeks == seeks + 1
    src.close()


def test_image_folder_and_offsets(tmp_path, clip):
    path, frames = clip
    folder_frames = make_frames(30, seed=5)
    folder = write_folder(tmp_path / "cam_b", folder_frames, start=1)
    with FrameSource({"cam_a": path, "cam_b": folder}, offsets={"cam_a": 4}) as src:
        assert src.camera_names == ["cam_a", "cam_b"]
        assert src.n_frames == 30  # min(40 - 4, 30)
        for f in [0, 29, 7, 8, 3]:
            out = src.read(f)
            assert identify(out["cam_a"], frames)[0] == f + 4
            np.testing.assert_array_equal(out["cam_b"], folder_frames[f])  # png is lossless
    with FrameSource({"cam_a": path, "cam_b": folder}, offsets={"cam_b": 25}) as src:
        assert src.n_frames == 5


def test_image_folder_numeric_order(tmp_path):
    frames = make_frames(12)
    folder = tmp_path / "cam"
    folder.mkdir()
    for i, f in enumerate(frames):  # unpadded names: 1.png ... 12.png must sort numerically
        cv2.imwrite(str(folder / f"{i + 1}.png"), f)
    src = FrameSource({"cam": folder})
    assert src.fps == 30.0 and src.n_frames == 12
    for f in range(12):
        np.testing.assert_array_equal(src.read(f)["cam"], frames[f])


def test_errors(tmp_path, clip):
    path, _ = clip
    src = FrameSource({"cam_a": path})
    with pytest.raises(IndexError, match=r"frame 40 is out of range: the capture has frames 0\.\.39"):
        src.read(40)
    with pytest.raises(IndexError, match="out of range"):
        src.read(-1)
    with pytest.raises(VideoNotFoundError, match=r"camera 'cam_z': footage not found at .*cam_z\.mp4"):
        FrameSource({"cam_a": path, "cam_z": tmp_path / "cam_z.mp4"})
    with pytest.raises(FileNotFoundError):
        find_video(tmp_path, "cam_q")
    with pytest.raises(VideoNotFoundError, match=r"camera 'cam_q'.*cam_q\.mp4"):
        find_video(tmp_path, "cam_q")
    with pytest.raises(FrameSourceError, match="offset -2"):
        FrameSource({"cam_a": path}, offsets={"cam_a": -2})
    with pytest.raises(FrameSourceError, match="unknown cameras"):
        FrameSource({"cam_a": path}, offsets={"cam_b": 1})
    with pytest.raises(FrameSourceError, match="no frame is covered"):
        FrameSource({"cam_a": path}, offsets={"cam_a": 40})
    (tmp_path / "empty").mkdir()
    with pytest.raises(FrameSourceError, match="holds no images"):
        FrameSource({"e": tmp_path / "empty"})
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all")
    with pytest.raises(FrameSourceError, match="camera 'bad'"):
        FrameSource({"bad": bad})


def test_find_video(tmp_path, clip):
    path, _ = clip
    (tmp_path / "cam_a.mp4").write_bytes(path.read_bytes())
    (tmp_path / "cam_b").mkdir()
    assert find_video(tmp_path, "cam_a") == tmp_path / "cam_a.mp4"
    assert find_video(tmp_path, "cam_b") == tmp_path / "cam_b"


# ---- load_capture ------------------------------------------------------------------------------
def _tiny_capture(root, clip, size_2=(W, H)):
    """Two cameras: cam_1 as mp4, cam_2 as a numbered png folder; a background plate for cam_1."""
    from markerless_mocap.core.capture.camera import Camera, rodrigues_to_matrix
    from markerless_mocap.core.capture.calibration import write_toml_calibration

    path, frames = clip
    K = np.array([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]])
    cams = [Camera("cam_1", K, [0.01, 0, 0, 0], np.eye(3), [0, 0, 3.0], W, H),
            Camera("cam_2", K, [], rodrigues_to_matrix([0, 0.5, 0]), [0.2, 0, 3.0], *size_2)]
    root.mkdir(parents=True, exist_ok=True)
    write_toml_calibration(cams, root / "calibration.toml", units="mm")
    (root / "videos").mkdir()
    (root / "videos" / "cam_1.mp4").write_bytes(path.read_bytes())
    folder_frames = make_frames(25, seed=9)
    write_folder(root / "videos" / "cam_2", folder_frames)
    (root / "background").mkdir()
    plate = np.full((H, W, 3), 77, np.uint8)
    cv2.imwrite(str(root / "background" / "cam_1.png"), plate)
    return cams, frames, folder_frames, plate


def test_load_capture(tmp_path, clip):
    from markerless_mocap.core.capture.capture import load_capture

    cams, frames, folder_frames, plate = _tiny_capture(tmp_path / "cap", clip)
    cap = load_capture(tmp_path / "cap", offsets={"cam_1": 2})
    try:
        assert cap.camera_names == ["cam_1", "cam_2"]
        assert cap.calibration_path.name == "calibration.toml"
        np.testing.assert_allclose(cap.camera("cam_2").t, cams[1].t, atol=1e-12)  # mm file read back in metres
        assert cap.frames.n_frames == 25 and cap.frames.fps == pytest.approx(25.0)
        out = cap.frames.read(10)
        assert identify(out["cam_1"], frames)[0] == 12
        np.testing.assert_array_equal(out["cam_2"], folder_frames[10])
        assert list(cap.backgrounds) == ["cam_1"]
        np.testing.assert_array_equal(cap.backgrounds["cam_1"], plate)
    finally:
        cap.close()


def test_load_capture_errors(tmp_path, clip):
    from markerless_mocap.core.capture.capture import CaptureError, load_capture

    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_capture(tmp_path / "nothing")
    _tiny_capture(tmp_path / "a", clip)
    (tmp_path / "a" / "videos" / "cam_1.mp4").unlink()
    with pytest.raises(VideoNotFoundError, match=r"camera 'cam_1': no footage found; expected .*videos/cam_1\.mp4"):
        load_capture(tmp_path / "a")
    _tiny_capture(tmp_path / "b", clip, size_2=(2 * W, 2 * H))
    with pytest.raises(CaptureError, match=r"camera 'cam_2': the calibration \(calibration\.toml\) says 320x240 but "
                                           r".*cam_2 is 160x120; the video looks resized by 0\.5"):
        load_capture(tmp_path / "b")
    _tiny_capture(tmp_path / "c", clip)
    cv2.imwrite(str(tmp_path / "c" / "background" / "cam_1.png"), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(CaptureError, match="background plate .* is 10x10"):
        load_capture(tmp_path / "c")


def test_load_capture_easymocap_sizes_from_videos(tmp_path, clip):
    """EasyMocap files without H_/W_: the image size comes from the footage."""
    from markerless_mocap.core.capture.calibration import write_easymocap_calibration
    from markerless_mocap.core.capture.capture import load_capture

    cams, *_ = _tiny_capture(tmp_path / "cap", clip)
    (tmp_path / "cap" / "calibration.toml").unlink()
    intri, _ = write_easymocap_calibration(cams, tmp_path / "cap")
    lines = [ln for ln in intri.read_text().splitlines() if not ln.startswith(("H_", "W_"))]
    intri.write_text("\n".join(lines) + "\n")
    from markerless_mocap.core.capture.calibration import MissingImageSizeError, read_calibration

    with pytest.raises(MissingImageSizeError):
        read_calibration(tmp_path / "cap")
    cap = load_capture(tmp_path / "cap")
    assert [c.size for c in cap.cameras] == [(W, H), (W, H)]
    cap.close()


def test_footage_a_few_pixels_off_the_calibration(tmp_path, clip):
    """Pose2Sim's demo: the calibration says 1088 px wide, two videos are 1080 (the sensor's padded
    width, same pixel grid). A few pixels at the right or bottom are accepted with one warning line;
    more than 16 px / 1 % per side, a resize, or a principal point outside the footage are refused."""
    import warnings

    from markerless_mocap.core.capture.camera import Camera
    from markerless_mocap.core.capture.capture import CaptureError, fit_camera_to_footage, load_capture

    # cam_2's calibration is 1 px wider and taller than its image folder (160x120; 1 % of 161 is 1.6 px): accepted
    cams, frames, folder_frames, _ = _tiny_capture(tmp_path / "cap", clip, size_2=(W + 1, H + 1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cap = load_capture(tmp_path / "cap")
    try:
        msgs = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
        assert len(msgs) == 1 and "\n" not in msgs[0]
        assert [w.filename for w in caught] == [str(tmp_path / "cap" / "videos" / "cam_2")] and caught[0].line is None
        assert re.search(r"camera 'cam_2': the calibration \(calibration\.toml\) says 161x121 but the footage is "
                         r"160x120: 1 x 1 px off", msgs[0]), msgs[0]
        assert cap.camera("cam_2").size == (W, H) and cap.camera("cam_1").size == (W, H)
        np.testing.assert_array_equal(cap.camera("cam_2").K, cams[1].K)     # same pixel grid, same K
        np.testing.assert_array_equal(cap.frames.read(3)["cam_2"], folder_frames[3])
    finally:
        cap.close()

    K = np.array([[1790.0, 0, 533.0], [0, 1790.0, 948.0], [0, 0, 1]])
    cam = Camera("cam01", K, [], np.eye(3), [0, 0, 3.0], 1088, 1920)
    with pytest.warns(UserWarning, match=r"camera 'cam01': .*1088x1920 but .*1080x1920: 8 x 0 px off"):
        assert fit_camera_to_footage(cam, 1080, 1920, "Calib.qca.txt", "videos/cam01.mp4").size == (1080, 1920)
    with pytest.warns(UserWarning, match="px off"):       # padded the other way (footage larger)
        assert fit_camera_to_footage(cam, 1096, 1920).size == (1096, 1920)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert fit_camera_to_footage(cam, 1088, 1920) is cam            # exact size: silent
    # refused: too far off (17 px > 16 px), over 1 % of a small side, a resize, principal point outside
    with pytest.raises(CaptureError, match=r"camera 'cam01': the calibration \(Calib\.qca\.txt\) says 1088x1920 but "
                                           r"videos/cam01\.mp4 is 1071x1920: 17 x 0 px off "
                                           r".*calibrate the cameras at 1071x1920"):
        fit_camera_to_footage(cam, 1071, 1920, "Calib.qca.txt", "videos/cam01.mp4")
    small = Camera("c", [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]], [], np.eye(3), [0, 0, 3.0], 640, 480)
    with pytest.raises(CaptureError, match="640x480 but its footage is 640x474: 0 x 6 px off"):
        fit_camera_to_footage(small, 640, 474)                          # 6 rows > 1 % of 480
    with pytest.raises(CaptureError, match="resized by 0.99375"):
        fit_camera_to_footage(small, 636, 477)
    edge = Camera("e", [[500.0, 0, 637.0], [0, 500.0, 239.5], [0, 0, 1]], [], np.eye(3), [0, 0, 3.0], 640, 480)
    with pytest.raises(CaptureError, match=r"principal point \(637\.0, 239\.5\) falls outside the footage"):
        fit_camera_to_footage(edge, 636, 480)
