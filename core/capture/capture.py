"""A capture folder -> cameras + synchronised frames + optional background plates.

Layout (kept stable, see docs architecture.md "Capture folder"):
    <capture>/calibration.toml  or  intri.yml + extri.yml  or  a *.qca.txt
    <capture>/videos/<camera name>.mp4   or  videos/<camera name>/ numbered images
    <capture>/background/<camera name>.png   optional empty-scene plate per camera
Camera names tie the calibration to the videos.
"""
from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from pathlib import Path


from ..errors import InputError
from .camera import Camera
from .calibration import MissingImageSizeError, find_calibration_file, read_calibration, require_two_cameras
from .frames import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS, FrameSource, FrameSourceError, find_video


class CaptureError(InputError):
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


# footage may differ from the calibrated size by this much per side (both limits hold): a sensor whose
# width is padded to a multiple of 16 (1088 vs 1080), or a few rows cropped by an encoder
SIZE_TOLERANCE_PX = 16
SIZE_TOLERANCE_FRACTION = 0.01


def fit_camera_to_footage(cam: Camera, w: int, h: int, calib_name: str = "the calibration",
                          video=None) -> Camera:
    """The camera for footage of w x h pixels.

    Same size: `cam` itself. A few pixels off (at most SIZE_TOLERANCE_PX and SIZE_TOLERANCE_FRACTION of
    the side, on each side) while the pixel grid is the same - the footage is the calibrated image
    cropped or padded at the right or bottom, so K still holds, and the principal point lies inside the
    footage: the camera with the footage's size, and a one-line warning. Anything else (a resized
    video, a different camera, a crop at the left or top that moves the principal point out) is a
    CaptureError naming the camera, both sizes and the fix."""
    W, H = cam.size
    if (w, h) == (W, H):
        return cam
    what = f"camera '{cam.name}': the calibration ({calib_name}) says {W}x{H} but {video or 'its footage'} is {w}x{h}"
    dw, dh = w - W, h - H
    if dw and dh and w * H == h * W:
        raise CaptureError(f"{what}; the video looks resized by {w / W:g}: resize it back to {W}x{H}, or scale the "
                           f"calibration (Camera.scaled({w / W:g}))")
    limit_w = min(SIZE_TOLERANCE_PX, SIZE_TOLERANCE_FRACTION * W)
    limit_h = min(SIZE_TOLERANCE_PX, SIZE_TOLERANCE_FRACTION * H)
    if abs(dw) > limit_w or abs(dh) > limit_h:
        raise CaptureError(f"{what}: {abs(dw)} x {abs(dh)} px off is more than a padded or cropped sensor explains "
                           f"(at most {SIZE_TOLERANCE_PX} px and {SIZE_TOLERANCE_FRACTION:.0%} per side); use the "
                           f"footage the calibration was made for, or calibrate the cameras at {w}x{h}")
    cx, cy = cam.K[0, 2], cam.K[1, 2]
    if not (0.0 <= cx <= w - 1 and 0.0 <= cy <= h - 1):
        raise CaptureError(f"{what}, and the principal point ({cx:.1f}, {cy:.1f}) falls outside the footage; "
                           f"the images do not share the calibration's pixel grid: recalibrate at {w}x{h}")
    # warn_explicit with no source line: Python prints exactly one line (<video>:0: UserWarning: message)
    warnings.warn_explicit(f"camera '{cam.name}': the calibration ({calib_name}) says {W}x{H} but the footage is "
                           f"{w}x{h}: {abs(dw)} x {abs(dh)} px off, taken as the same pixel grid cropped/padded at "
                           f"the right or bottom; the camera is used at {w}x{h}", UserWarning,
                           str(video or calib_name), 0, module=__name__)
    return dataclasses.replace(cam, width=int(w), height=int(h))


def _load_backgrounds(folder: Path, cameras: list) -> dict | None:
    import cv2

    bg_dir = folder / "background"
    if not bg_dir.is_dir():
        return None
    plates = {}
    for cam in cameras:
        path = next((bg_dir / f"{cam.name}{ext}" for ext in IMAGE_EXTENSIONS
                     if (bg_dir / f"{cam.name}{ext}").is_file()), None)
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


def load_capture(folder, units: str | None = None, offsets: dict | None = None, cache_size: int = 4) -> Capture:
    """Read a capture folder: calibration (metres), per-camera footage, optional background plates.

    units: the calibration's length unit if the file does not say it ('m', 'cm', 'mm').
    offsets: {camera name: first frame of that camera's footage that belongs to capture frame 0}.
    cache_size: decoded frames kept per camera. Tracking reads each frame once or twice in order, so a few
    suffice; the memory stays flat however long the take (64 HD frames x 4 cameras would hold 1.6 GB).
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
    require_two_cameras(calib_path, cameras)
    paths = {cam.name: find_video(videos_dir, cam.name) for cam in cameras}
    try:
        frames = FrameSource(paths, offsets=offsets, cache_size=cache_size)
    except FrameSourceError as exc:
        raise CaptureError(f"{folder}: {exc}") from None
    try:
        cameras = [fit_camera_to_footage(cam, *frames.image_size(cam.name), calib_path.name, paths[cam.name])
                   for cam in cameras]
        backgrounds = _load_backgrounds(folder, cameras)
    except Exception:
        frames.close()
        raise
    return Capture(cameras, frames, backgrounds, folder, calib_path)
