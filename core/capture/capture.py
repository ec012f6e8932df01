"""A capture folder -> cameras + synchronised frames + optional background plates.

Layout (kept stable, see docs architecture.md "Capture folder"):
    <capture>/calibration.toml  or  intri.yml + extri.yml  or  a *.qca.txt
    <capture>/videos/<camera name>.mp4   or  videos/<camera name>/ numbered images
    <capture>/background/<camera name>.png   optional empty-scene plate per camera
Camera names tie the calibration to the videos.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


from ..camera import Camera
from .calibration import MissingImageSizeError, find_calibration_file, read_calibration
from .frames import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS, FrameSource, FrameSourceError, find_video


class CaptureError(ValueError):
    """A capture folder that does not fit together (missing footage, sizes that disagree...)."""


class CaptureNotFoundError(CaptureError, FileNotFoundError):
    pass


@dataclass
class Capture:
    cameras: list  # list[Camera], in calibration order (natural sort by name)
    frames: FrameSource
    backgrounds: dict | None  # {camera name: BGR uint8 plate} for the cameras that have one, or None
    folder: Path
    calibration_path: Path | None = None

    def camera(self, name: str) -> Camera:
        for cam in self.cameras:
            if cam.name == name:
                return cam
        raise KeyError(f"no camera '{name}' in {self.folder}; cameras are {[c.name for c in self.cameras]}")

    @property
    def camera_names(self) -> list:
        return [c.name for c in self.cameras]

    def close(self) -> None:
        self.frames.close()


def _footage_sizes(videos_dir: Path) -> dict:
    """{name: (W, H)} for every video / image folder in videos/ (used when the calibration omits sizes)."""
    import cv2

    sizes = {}
    if not videos_dir.is_dir():
        return sizes
    for entry in sorted(videos_dir.iterdir()):
        if entry.is_dir():
            images = sorted(p for p in entry.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS)
            img = cv2.imread(str(images[0]), cv2.IMREAD_COLOR) if images else None
            if img is not None:
                sizes[entry.name] = (img.shape[1], img.shape[0])
        elif entry.suffix.lower() in VIDEO_EXTENSIONS:
            cap = cv2.VideoCapture(str(entry))
            if cap.isOpened():
                sizes[entry.stem] = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
            cap.release()
    return sizes


def _load_backgrounds(folder: Path, cameras: list) -> dict | None:
    import cv2

    bg_dir = folder / "background"
    if not bg_dir.is_dir():
        return None
    plates = {}
    for cam in cameras:
        path = next((bg_dir / f"{cam.name}{ext}" for ext in IMAGE_EXTENSIONS if (bg_dir / f"{cam.name}{ext}").is_file()),
                    None)
        if path is None:
            continue
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise CaptureError(f"camera '{cam.name}': OpenCV cannot read the background plate {path}")
        if (img.shape[1], img.shape[0]) != cam.size:
            raise CaptureError(f"camera '{cam.name}': background plate {path} is {img.shape[1]}x{img.shape[0]} but "
                               f"the camera is {cam.width}x{cam.height}; the plate must be shot at the video size")
        plates[cam.name] = img
    return plates or None


def load_capture(folder, units: str | None = None, offsets: dict | None = None, cache_size: int = 64) -> Capture:
    """Read a capture folder: calibration (metres), per-camera footage, optional background plates.

    units: the calibration's length unit if the file does not say it ('m', 'cm', 'mm').
    offsets: {camera name: first frame of that camera's footage that belongs to capture frame 0}.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise CaptureNotFoundError(f"capture folder {folder} does not exist")
    calib_path = find_calibration_file(folder)
    videos_dir = folder / "videos"
    try:
        cameras = read_calibration(calib_path, units=units)
    except MissingImageSizeError:
        cameras = read_calibration(calib_path, units=units, image_sizes=_footage_sizes(videos_dir))
    paths = {cam.name: find_video(videos_dir, cam.name) for cam in cameras}
    try:
        frames = FrameSource(paths, offsets=offsets, cache_size=cache_size)
    except FrameSourceError as exc:
        raise CaptureError(f"{folder}: {exc}") from None
    try:
        for cam in cameras:
            w, h = frames.image_size(cam.name)
            if (w, h) != cam.size:
                hint = ""
                if w * cam.height == h * cam.width:
                    hint = (f"; the video looks resized by {w / cam.width:g}: resize it back, or scale the calibration "
                            f"(Camera.scaled({w / cam.width:g}))")
                raise CaptureError(f"camera '{cam.name}': the calibration ({calib_path.name}) says "
                                   f"{cam.width}x{cam.height} but {paths[cam.name]} is {w}x{h}{hint}")
        backgrounds = _load_backgrounds(folder, cameras)
    except Exception:
        frames.close()
        raise
    return Capture(cameras, frames, backgrounds, folder, calib_path)
