"""Synchronised random access to the frames of several cameras (videos or numbered image folders).

Frame f of the capture is frame f + offsets[camera] of that camera's footage. Videos are decoded
with OpenCV: asking for the frame after the last one read continues sequentially (fast and
exact); small forward jumps are skipped with grab(); anything else seeks with CAP_PROP_POS_FRAMES.
Each camera keeps a bounded LRU cache of decoded frames.
"""
from __future__ import annotations

import re
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from ..errors import InputError

VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv")
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
_GRAB_AHEAD = 16  # forward jumps up to this many frames are cheaper to grab() than to seek
DEFAULT_FPS = 30.0


class FrameSourceError(InputError):
    """Footage that cannot be used (unreadable, empty, inconsistent sizes, bad offsets)."""


class VideoNotFoundError(FrameSourceError, FileNotFoundError):
    pass


def find_video(videos_dir, camera_name: str) -> Path:
    """videos/<name>.<video ext> or videos/<name>/ (numbered images); error naming the expected path."""
    videos_dir = Path(videos_dir)
    folder = videos_dir / camera_name
    if folder.is_dir():
        return folder
    for ext in VIDEO_EXTENSIONS:
        for candidate in (videos_dir / f"{camera_name}{ext}", videos_dir / f"{camera_name}{ext.upper()}"):
            if candidate.is_file():
                return candidate
    raise VideoNotFoundError(
        f"camera '{camera_name}': no footage found; expected {videos_dir / (camera_name + '.mp4')} (or another video "
        f"format: {', '.join(VIDEO_EXTENSIONS)}) or a folder {folder}/ of numbered images")


def _number_key(path: Path):
    numbers = re.findall(r"\d+", path.stem)
    return (int(numbers[-1]) if numbers else -1, path.name)


class _ImageFolderReader:
    def __init__(self, name: str, folder: Path):
        import cv2

        self.name, self.path = name, folder
        self.files = sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS), key=_number_key)
        if not self.files:
            raise FrameSourceError(f"camera '{name}': {folder} holds no images ({', '.join(IMAGE_EXTENSIONS)})")
        first = cv2.imread(str(self.files[0]), cv2.IMREAD_COLOR)
        if first is None:
            raise FrameSourceError(f"camera '{name}': OpenCV cannot read the image {self.files[0]}")
        self.height, self.width = first.shape[:2]
        self.n_frames = len(self.files)
        self.fps = None

    def read(self, index: int) -> np.ndarray:
        import cv2

        image = cv2.imread(str(self.files[index]), cv2.IMREAD_COLOR)
        if image is None:
            raise FrameSourceError(f"camera '{self.name}': OpenCV cannot read the image {self.files[index]}")
        if image.shape[:2] != (self.height, self.width):
            raise FrameSourceError(f"camera '{self.name}': {self.files[index].name} is "
                                   f"{image.shape[1]}x{image.shape[0]} but the first image is "
                                   f"{self.width}x{self.height}; all images must match")
        return image

    def close(self):
        pass


class _VideoReader:
    def __init__(self, name: str, path: Path):
        import cv2

        self.name, self.path = name, path
        self.cap = cv2.VideoCapture(str(path))
        if not self.cap.isOpened():
            raise FrameSourceError(f"camera '{name}': OpenCV cannot open the video {path} (unsupported codec or "
                                   "damaged file); convert it to H.264 mp4 or export numbered images")
        self.width = int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        # The container's count; rarely off by a frame or two for variable-frame-rate files.
        self.n_frames = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(self.cap.get(cv2.CAP_PROP_FPS))
        self.fps = fps if np.isfinite(fps) and fps > 0 else None
        if self.n_frames <= 0 or self.width <= 0 or self.height <= 0:
            self.cap.release()
            raise FrameSourceError(f"camera '{name}': the video {path} has no frames (empty or cut short while "
                                   "recording); replace it with the camera's full recording")
        self.next_index = 0  # the frame the next cap.read() returns
        self.seeks = 0  # number of random seeks (for tests and profiling)

    def read(self, index: int) -> np.ndarray:
        import cv2

        gap = index - self.next_index
        if gap < 0 or gap > _GRAB_AHEAD:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            self.seeks += 1
        else:
            for _ in range(gap):
                self.cap.grab()
        ok, image = self.cap.read()
        if not ok or image is None:
            self.next_index = -1  # position unknown: force a seek next time
            raise FrameSourceError(f"camera '{self.name}': could not decode frame {index} of {self.path} "
                                   f"(the file reports {self.n_frames} frames)")
        self.next_index = index + 1
        return image

    def close(self):
        self.cap.release()


class FrameSource:
    """Synchronised frames of several cameras: read(f) -> {camera name: BGR uint8 image}."""

    def __init__(self, paths: dict, offsets: dict | None = None, cache_size: int = 4, fps: float | None = None):
        if not paths:
            raise FrameSourceError("no cameras given: pass {camera name: video path or image folder}")
        offsets = dict(offsets or {})
        unknown = set(offsets) - set(paths)
        if unknown:
            raise FrameSourceError(f"offsets given for unknown cameras {sorted(unknown)}; cameras are {list(paths)}")
        if cache_size < 0:
            raise FrameSourceError(f"cache_size must be >= 0; got {cache_size}")
        self.camera_names = [str(n) for n in paths]
        self.offsets = {}
        for name in self.camera_names:
            off = offsets.get(name, 0)
            if int(off) != off or off < 0:
                raise FrameSourceError(f"camera '{name}': frame offset {off} must be a whole number >= 0 (to start a "
                                       "camera later, give the other cameras larger offsets instead)")
            self.offsets[name] = int(off)
        self.cache_size = int(cache_size)
        # The tracker reads the next frame in a worker thread while it finishes this one: one reader at a time,
        # and close() waits for a read under way.
        self._lock = threading.RLock()
        self._readers = {}
        self._caches = {}
        try:
            for name, path in zip(self.camera_names, paths.values()):
                path = Path(path)
                if path.is_dir():
                    reader = _ImageFolderReader(name, path)
                elif path.is_file():
                    reader = _VideoReader(name, path)
                else:
                    raise VideoNotFoundError(f"camera '{name}': footage not found at {path} (expected a video file "
                                             "or a folder of numbered images)")
                self._readers[name] = reader
                self._caches[name] = OrderedDict()
        except Exception:
            self.close()
            raise
        self.n_frames = max(0, min(r.n_frames - self.offsets[n] for n, r in self._readers.items()))
        if self.n_frames == 0:
            raise FrameSourceError("after the frame offsets no frame is covered by every camera: "
                                   + ", ".join(f"'{n}': {r.n_frames} frames, offset {self.offsets[n]}"
                                               for n, r in self._readers.items()))
        rates = {n: r.fps for n, r in self._readers.items() if r.fps}
        if not fps:
            _require_one_frame_rate(rates, self.close)
        self.fps = float(fps) if fps else (float(next(iter(rates.values()))) if rates else DEFAULT_FPS)

    def __len__(self) -> int:
        return self.n_frames

    @property
    def frames_per_camera(self) -> dict:
        """{camera name: capture frames its footage covers} (after its offset)."""
        return {n: r.n_frames - self.offsets[n] for n, r in self._readers.items()}

    def shorter_footage_note(self) -> str | None:
        """One line naming the cameras whose footage ends before the others', or None when all are as long."""
        counts = self.frames_per_camera
        longest = max(counts.values())
        short = [n for n, c in counts.items() if c < longest]
        if not short:
            return None
        named = ", ".join(f"'{n}' ({self._readers[n].path.name}) has {counts[n]} frames" for n in short)
        return (f"{named}, the other cameras up to {longest}: only the {self.n_frames} frames every camera "
                f"covers (0-{self.n_frames - 1}) are tracked")

    def require_frames(self, frames) -> list:
        """The asked capture frames, all of them covered by every camera; otherwise a FrameSourceError
        naming the camera whose footage ends too early, its frame count and the fix."""
        frames = [int(f) for f in frames]
        if not frames:
            raise FrameSourceError("no frames asked for")
        first, last = min(frames), max(frames)
        asked = f"frames {first}-{last}" if first != last else f"frame {first}"
        if first < 0:
            raise FrameSourceError(f"{asked} asked for: capture frames count from 0; choose a range within "
                                   f"0-{self.n_frames - 1}")
        counts = self.frames_per_camera
        if last < self.n_frames:
            return frames
        if all(c <= last for c in counts.values()):
            raise FrameSourceError(f"{asked} asked for, but the capture has {self.n_frames} frames "
                                   f"(0-{self.n_frames - 1}); choose a range within 0-{self.n_frames - 1}")
        short = [n for n, c in counts.items() if c <= last]
        named = "; ".join(f"camera '{n}' ({self._readers[n].path.name}) has only {counts[n]} frames "
                          f"(0-{counts[n] - 1})" for n in short)
        raise FrameSourceError(f"{asked} asked for, but {named}, while other cameras reach frame {last}: track "
                               f"frames {first}-{self.n_frames - 1} at most, or replace the short footage with "
                               "the camera's full recording of the take")

    def image_size(self, name: str) -> tuple[int, int]:
        reader = self._reader(name)
        return reader.width, reader.height

    def source_path(self, name: str) -> Path:
        return self._reader(name).path

    def _reader(self, name):
        if name not in self._readers:
            raise KeyError(f"no camera '{name}'; cameras are {self.camera_names}")
        return self._readers[name]

    def read_camera(self, name: str, frame: int) -> np.ndarray:
        """One camera's image at capture frame `frame` (BGR uint8). The cached array is shared: do not modify it."""
        self._check(frame)
        reader, cache = self._reader(name), self._caches[name]
        index = int(frame) + self.offsets[name]
        with self._lock:
            image = cache.get(index)
            if image is not None:
                cache.move_to_end(index)
                return image
            image = reader.read(index)
            if self.cache_size:
                cache[index] = image
                while len(cache) > self.cache_size:
                    cache.popitem(last=False)
            return image

    def read(self, frame: int) -> dict:
        """{camera name: BGR uint8 image} at capture frame `frame` (0-based)."""
        self._check(frame)
        return {name: self.read_camera(name, frame) for name in self.camera_names}

    def _check(self, frame) -> None:
        if int(frame) != frame:
            raise IndexError(f"frame {frame!r} is not a whole number")
        if not 0 <= frame < self.n_frames:
            raise IndexError(f"frame {frame} is out of range: the capture has frames 0..{self.n_frames - 1}")

    def close(self) -> None:
        with self._lock:
            for reader in self._readers.values():
                reader.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# frame rates further apart than this (relative) are different recordings, not container rounding
_FPS_TOLERANCE = 0.001


def _require_one_frame_rate(rates: dict, close) -> None:
    """Videos recorded at different frame rates cannot be tracked frame by frame together."""
    if len(rates) < 2:
        return
    items = sorted(rates.items(), key=lambda kv: kv[1])
    (slow, slow_fps), (fast, fast_fps) = items[0], items[-1]
    if (fast_fps - slow_fps) / fast_fps > _FPS_TOLERANCE:
        close()
        raise FrameSourceError(f"camera '{slow}' runs at {slow_fps:g} fps but camera '{fast}' at {fast_fps:g} fps; "
                               "frames are matched by number, so convert the videos to one frame rate first "
                               f"(e.g. ffmpeg -i in.mp4 -r {slow_fps:g} out.mp4)")
