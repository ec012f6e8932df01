"""FrameSource: frame-exact random access in videos and image folders, offsets, cache, errors."""
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
