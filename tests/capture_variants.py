"""Copies of a bundled sample capture with one thing broken: a camera's video cut short, re-timed,
blanked or cropped. Built in a test's temporary folder; nothing is written into the repository."""
import shutil
from pathlib import Path

import cv2
import numpy as np

from scene_helpers import scene_dir


def copy_capture(dest, name="walk"):
    """The scene's calibration, videos and plates (not the ground truth) copied to `dest`."""
    src = scene_dir(name)
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    for entry in ("calibration.toml", "videos", "background"):
        if (src / entry).is_dir():
            shutil.copytree(src / entry, dest / entry)
        elif (src / entry).is_file():
            shutil.copy(src / entry, dest / entry)
    return dest


def rewrite_video(path, keep=None, fps=None, edit=None):
    """Re-encode a video in place: the first `keep` frames, at `fps`, each frame passed through edit(i, img)."""
    path = Path(path)
    cap = cv2.VideoCapture(str(path))
    rate = fps or cap.get(cv2.CAP_PROP_FPS)
    frames = []
    while keep is None or len(frames) < keep:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(edit(len(frames), img) if edit else img)
    cap.release()
    tmp = path.with_name("rewritten" + path.suffix)
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), rate, (w, h))
    for img in frames:
        writer.write(img)
    writer.release()
    tmp.replace(path)
    return len(frames)


def blank(_i, img):
    return np.zeros_like(img)
