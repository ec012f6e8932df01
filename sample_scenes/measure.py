"""Measure what makes a rendered sample scene hard (the figures in docs/sample-scenes.md).

    .venv/bin/python sample_scenes/measure.py --scene busy [--scene playground ...]

Per camera: the range of the video's mean grey level and of its blue/red ratio over the clip; the
silhouette IoU against the true masks of core's BackgroundModel estimated from the clip (median of
25 evenly spaced frames, as tests/test_scene_likelihood.py does - no scene here has plates except
walk); and the colour contrast between the person and what is behind them (mean CIELAB distance
between the frame inside the true mask and the clip-median background at the same pixels).
"""
import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))      # the engine package `core` (bpy-free), as generate.py does

from core import features  # noqa: E402
from core.capture.capture import load_capture  # noqa: E402


def measure(folder):
    cap = load_capture(folder)
    n = cap.frames.n_frames
    out = {}
    try:
        for cam in cap.cameras:
            grey, br = [], []
            for f in range(n):
                m = cap.frames.read_camera(cam.name, f).reshape(-1, 3).astype(np.float64).mean(axis=0)
                grey.append(m.mean())
                br.append(m[0] / m[2])
            frames = [cap.frames.read_camera(cam.name, int(f)) for f in np.linspace(0, n - 1, 25).round()]
            model = features.BackgroundModel.from_frames(frames)
            ious, contrast = [], []
            for mf in sorted((Path(folder) / "gt_masks" / cam.name).glob("*.png")):
                truth = cv2.imread(str(mf), cv2.IMREAD_GRAYSCALE) > 127
                img = cap.frames.read_camera(cam.name, int(mf.stem))
                ious.append(features.silhouette_iou(model.silhouette(img), truth))
                lab = cv2.cvtColor(img, cv2.COLOR_BGR2LAB).astype(np.float64)
                bg8 = np.clip(np.asarray(model.background, np.float64) + 0.5, 0, 255).astype(np.uint8)
                lab_bg = cv2.cvtColor(bg8, cv2.COLOR_BGR2LAB).astype(np.float64)   # 8-bit Lab: L, a, b in 0..255
                contrast.append(float(np.linalg.norm(lab[truth] - lab_bg[truth], axis=1).mean()))
            out[cam.name] = dict(grey=[round(min(grey), 1), round(max(grey), 1)],
                                 grey_ratio=round(max(grey) / min(grey), 2),
                                 blue_red=[round(min(br), 3), round(max(br), 3)],
                                 clip_median_iou=[round(float(v), 3) for v in ious],
                                 clip_median_iou_mean=round(float(np.mean(ious)), 3),
                                 person_vs_background_lab=round(float(np.mean(contrast)), 1))
    finally:
        cap.close()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", action="append", required=True)
    args = ap.parse_args(argv)
    for s in args.scene:
        res = measure(HERE / s)
        print(s, json.dumps(res, indent=1))
        ious = [v["clip_median_iou_mean"] for v in res.values()]
        print(f"{s}: clip-median IoU mean over cameras {np.mean(ious):.3f}; grey ratio "
              f"{min(v['grey_ratio'] for v in res.values())}-{max(v['grey_ratio'] for v in res.values())}")


if __name__ == "__main__":
    main()
