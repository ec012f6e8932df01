"""Contact sheet of a tracking result: every N-th tracked frame (rows) in every camera (columns).

    python -m markerless_mocap.tools.contact_sheet --result RESULT [--capture CAPTURE] [--every 10]
                                                   [--out RESULT/contact_sheet.jpg] [--tile-height 320]

Tiles come from the result's overlay videos (RESULT/overlay/<camera>.mp4, the projected model as the
tracker drew it, one video frame per tracked frame). A result written with --no-overlays has none:
then give --capture, and the result's joints (joints.npz) are projected onto the footage as a
skeleton. Each tile is labelled with the camera and the capture frame. A dev tool: not shipped in
the extension.
"""
import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

# CMU / MakeHuman bone heads joined for the skeleton drawing (the --capture fallback)
LIMBS = [("Hips", "LowerBack"), ("LowerBack", "Spine"), ("Spine", "Spine1"), ("Spine1", "Neck"), ("Neck", "Head"),
         ("Spine1", "LeftArm"), ("LeftArm", "LeftForeArm"), ("LeftForeArm", "LeftHand"),
         ("Spine1", "RightArm"), ("RightArm", "RightForeArm"), ("RightForeArm", "RightHand"),
         ("Hips", "LeftUpLeg"), ("LeftUpLeg", "LeftLeg"), ("LeftLeg", "LeftFoot"), ("LeftFoot", "LeftToeBase"),
         ("Hips", "RightUpLeg"), ("RightUpLeg", "RightLeg"), ("RightLeg", "RightFoot"), ("RightFoot", "RightToeBase")]


def result_frames(result):
    """Capture frame numbers of the tracked frames, in the order they were written."""
    result = Path(result)
    if (result / "joints.npz").is_file():
        with np.load(result / "joints.npz") as z:
            return [int(f) for f in z["frames"]]
    report = json.loads((result / "report.json").read_text())
    return [int(f["frame"]) for f in report["frames"]]


def _label(img, text):
    cv2.rectangle(img, (0, 0), (img.shape[1], 22), (0, 0, 0), -1)
    cv2.putText(img, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def _tile(img, height):
    w = max(1, round(img.shape[1] * height / img.shape[0]))
    return cv2.resize(img, (w, height), interpolation=cv2.INTER_AREA)


def _skeleton(img, cam, names, joints):
    uv, depth = cam.project_with_depth(joints)
    idx = {n: k for k, n in enumerate(names)}
    th = max(2, round(img.shape[0] / 300))
    for a, b in LIMBS:
        if a in idx and b in idx and depth[idx[a]] > 0 and depth[idx[b]] > 0:
            colour = (255, 128, 0) if "Left" in b else (0, 128, 255) if "Right" in b else (0, 255, 255)
            cv2.line(img, tuple(np.round(uv[idx[a]]).astype(int)), tuple(np.round(uv[idx[b]]).astype(int)),
                     colour, th, cv2.LINE_AA)
    return img


def contact_sheet(result, capture=None, every=10, tile_height=320):
    """The sheet as a BGR image: rows = every `every`-th tracked frame, columns = cameras."""
    result = Path(result)
    frames = result_frames(result)
    picks = list(range(0, len(frames), max(1, int(every))))
    overlay = result / "overlay"
    videos = sorted(overlay.glob("*.mp4")) if overlay.is_dir() else []
    rows = {i: [] for i in picks}
    if videos:
        for path in videos:
            cap = cv2.VideoCapture(str(path))
            for i in picks:
                cap.set(cv2.CAP_PROP_POS_FRAMES, i)
                ok, img = cap.read()
                if not ok:
                    img = np.zeros((tile_height, tile_height, 3), np.uint8)
                rows[i].append(_label(_tile(img, tile_height), f"{path.stem}  frame {frames[i]}"))
            cap.release()
    elif capture is not None:
        from ..core.capture.capture import load_capture
        from ..core.results import load_joints

        names, jframes, joints = load_joints(result / "joints.npz")
        cap = load_capture(capture)
        try:
            for i in picks:
                images = cap.frames.read(int(jframes[i]))
                for cam in cap.cameras:
                    img = _skeleton(images[cam.name].copy(), cam, names, joints[i])
                    rows[i].append(_label(_tile(img, tile_height), f"{cam.name}  frame {jframes[i]}"))
        finally:
            cap.close()
    else:
        raise FileNotFoundError(f"{overlay}: no overlay videos; give --capture to draw the result's joints instead")
    width = max(sum(t.shape[1] for t in r) for r in rows.values())
    out = []
    for i in picks:
        row = np.hstack(rows[i])
        out.append(np.pad(row, ((0, 0), (0, width - row.shape[1]), (0, 0))))
    return np.vstack(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--result", required=True, help="a track result folder (joints.npz, overlay/)")
    ap.add_argument("--capture", help="capture folder, to draw the joints when the result has no overlay videos")
    ap.add_argument("--every", type=int, default=10, help="every N-th tracked frame (default 10)")
    ap.add_argument("--tile-height", type=int, default=320, help="height of one view's tile in pixels")
    ap.add_argument("--out", help="image to write (default RESULT/contact_sheet.jpg)")
    args = ap.parse_args(argv)
    sheet = contact_sheet(args.result, args.capture, args.every, args.tile_height)
    out = Path(args.out) if args.out else Path(args.result) / "contact_sheet.jpg"
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), sheet, [cv2.IMWRITE_JPEG_QUALITY, 85]):
        sys.exit(f"could not write {out}")
    print(f"{out}: {sheet.shape[1]}x{sheet.shape[0]}")


if __name__ == "__main__":
    main()
