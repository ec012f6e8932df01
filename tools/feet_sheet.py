"""A contact sheet of the feet, to see whether planted feet slide on footage without ground truth.

For each view, one crop around everywhere the tracked feet go over the frames shown (the same crop in every row, so
a foot that slides moves across it), every --every frames: the locked take's ankles and balls of the feet
(joints.npz) in green, the take before locking (joints_unpinned.npz) in red, a ring around a foot point while
report.json's foot locking pinned it. Also prints, per pinned contact, how far its points move in the locked take
and in the unpinned one, in pixels of each view (the footage says whether the foot was still).

    .venv/bin/python tools/feet_sheet.py RESULT CAPTURE --out feet.jpg [--every 5] [--frames 0-99] [--views cam1,cam2]
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

FOOT_POINTS = ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")
MARGIN_PX = 60


def load_points(path, frames=None):
    from markerless_mocap.core.results.result_folder import load_joints

    names, got, positions = load_joints(path)
    at = {int(f): i for i, f in enumerate(got)}
    frames = [int(f) for f in got] if frames is None else [f for f in frames if f in at]
    return frames, positions[[at[f] for f in frames]][:, [names.index(n) for n in FOOT_POINTS]]


def pinned_points(report, frames):
    """{frame: set of FOOT_POINTS indices pinned then} (a contact is one foot point's: its bone's head)."""
    pinned = {f: set() for f in frames}
    for contact in report.get("foot_locking", {}).get("contacts", []):
        for f in range(contact["frames"][0], contact["frames"][1] + 1):
            if f in pinned and contact["bone"] in FOOT_POINTS:
                pinned[f].add(FOOT_POINTS.index(contact["bone"]))
    return pinned


def contact_drift(report, cameras, frames, locked, unpinned):
    """Per pinned contact: the mean over views of its points' largest pixel distance from their first position."""
    at = {f: i for i, f in enumerate(frames)}
    rows = []
    for contact in report.get("foot_locking", {}).get("contacts", []):
        span = [at[f] for f in range(contact["frames"][0], contact["frames"][1] + 1) if f in at]
        if len(span) < 2 or contact["bone"] not in FOOT_POINTS:
            continue
        side = [FOOT_POINTS.index(contact["bone"])]
        drift = {}
        for label, take in (("locked", locked), ("unpinned", unpinned)):
            per_view = []
            for cam in cameras:
                uv = cam.project(take[span][:, side].reshape(-1, 3)).reshape(len(span), len(side), 2)
                per_view.append(np.linalg.norm(uv - uv[:1], axis=-1).max())
            drift[label] = float(np.mean(per_view))
        rows.append(dict(bone=contact["bone"], frames=contact["frames"], **drift))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("result", type=Path)
    ap.add_argument("capture", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--frames", help="A-B (default: every frame of the result)")
    ap.add_argument("--views", help="camera names, comma-separated (default: all)")
    args = ap.parse_args(argv)

    import cv2

    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.results.overlay import contact_sheet

    capture = load_capture(args.capture)
    cameras = [c for c in capture.cameras if not args.views or c.name in args.views.split(",")]
    wanted = None
    if args.frames:
        a, b = (int(x) for x in args.frames.split("-"))
        wanted = range(a, b + 1)
    frames, locked = load_points(args.result / "joints.npz", wanted)
    unpinned_file = args.result / "joints_unpinned.npz"
    _, unpinned = load_points(unpinned_file if unpinned_file.is_file() else args.result / "joints.npz", frames)
    report_file = args.result / "report.json"
    report = json.loads(report_file.read_text()) if report_file.is_file() else {}
    pinned = pinned_points(report, frames)
    shown = frames[::max(1, args.every)]

    boxes = {}
    for cam in cameras:   # one crop per view: every foot point of both takes over the frames shown, and a margin
        uv = cam.project(np.concatenate([locked, unpinned]).reshape(-1, 3))
        lo = np.floor(uv.min(axis=0) - MARGIN_PX).astype(int)
        hi = np.ceil(uv.max(axis=0) + MARGIN_PX).astype(int)
        boxes[cam.name] = (np.maximum(lo, 0), np.minimum(hi, [cam.width, cam.height]))
    rows, labels = [], []
    for f in shown:
        images = capture.frames.read(f)
        k = frames.index(f)
        cells = []
        for cam in cameras:
            img = images[cam.name].copy()
            for take, colour, radius in ((locked, (0, 200, 0), 5), (unpinned, (0, 0, 255), 2)):  # red on top
                for p, (u, v) in enumerate(cam.project(take[k])):
                    cv2.circle(img, (int(round(u)), int(round(v))), radius, colour, -1, cv2.LINE_AA)
                    if take is locked and p in pinned[f]:
                        cv2.circle(img, (int(round(u)), int(round(v))), 9, (255, 255, 255), 2, cv2.LINE_AA)
            (x0, y0), (x1, y1) = boxes[cam.name]
            cells.append(img[y0:y1, x0:x1])
        rows.append(cells)
        labels.append(f"frame {f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), contact_sheet(rows, cell_height=240, label_rows=labels))
    print(f"feet sheet: {args.out} ({len(rows)} frames x {len(cameras)} views; green locked, red unpinned, "
          "ringed while pinned)")
    drift = contact_drift(report, cameras, frames, locked, unpinned)
    if not drift:
        print("no pinned contacts in report.json")
    for row in drift:
        print(f"{row['bone']:<9} frames {row['frames'][0]}-{row['frames'][1]}: largest move in the image, mean over "
              f"views: locked {row['locked']:.1f} px, unpinned {row['unpinned']:.1f} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
