"""Does the landmark model tell a person's back from their front? Per view and frame of a tracked take's landmarks
(keypoints.npz), against the truth:

- the view sees the back: the truth's trunk faces away from the camera by more than 90 degrees;
- the landmarks lie about the sides: the truth's shoulders and hips fit the landmarks better swapped left for right;
- the landmarks read as a back: the left shoulder and hip lie on the image's left of the right ones, by more than
  --margin of the trunk's height in the picture (a front shows them the other way round).

    .venv/bin/python tools/landmark_facing.py sample_scenes/dance RESULT [--frames 67-86]

Needs bpy (the subject .blend gives the rig; tools/hidden_landmarks.py reads the truth and the landmarks).
docs/measurements.md, "Tried and not adopted", quotes its figures.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hidden_landmarks import truth_and_landmarks  # noqa: E402  (a sibling tool, not a package)

TRUNK = (11, 12, 23, 24)  # BlazePose: left / right shoulder, left / right hip


def view_rows(scene, result):
    """Per (frame, view): frame, view, sees the back, landmarks swapped, landmarks' back reading (signed, trunk
    heights), nose visibility."""
    body, rig, frames, poses, cameras, uv_all, vis_all, kept = truth_and_landmarks(scene, result)
    landmarks = list(rig.landmarks)
    trunk = [landmarks.index(k) for k in TRUNK]
    swapped = [landmarks.index(k) for k in (12, 11, 24, 23)]
    truth_at = {int(f): i for i, f in enumerate(frames)}
    rows = []
    for j, frame in enumerate(kept):
        if int(frame) not in truth_at:
            continue
        points = rig.world(body, poses[truth_at[int(frame)]][None])[0]
        l_shoulder, r_shoulder, l_hip, r_hip = (points[i] for i in trunk)
        across = l_shoulder - r_shoulder + l_hip - r_hip
        facing = np.array([across[1], -across[0], 0.0])  # the trunk's forward in the floor plane (z up)
        facing /= np.linalg.norm(facing)
        centre = points[trunk].mean(axis=0)
        for c, camera in enumerate(cameras):
            vis = vis_all[j, c]
            if vis[list(TRUNK)].min() < 0.1:
                continue
            truth_uv = camera.project(points)
            uv = uv_all[j, c][rig.landmarks]
            as_labelled = np.linalg.norm(uv[trunk] - truth_uv[trunk], axis=1).mean()
            as_swapped = np.linalg.norm(uv[swapped] - truth_uv[trunk], axis=1).mean()
            to_camera = camera.center - centre
            to_camera[2] = 0.0
            sees_back = facing @ to_camera < 0
            left, right = (uv[trunk[0]] + uv[trunk[2]]) / 2, (uv[trunk[1]] + uv[trunk[3]]) / 2
            up = (uv[trunk[0]] + uv[trunk[1]] - uv[trunk[2]] - uv[trunk[3]]) / 2
            side = left - right
            back_reading = -(up[0] * side[1] - up[1] * side[0]) / (up @ up + 1e-9)  # > 0: reads as a back
            rows.append((int(frame), c, sees_back, as_swapped < as_labelled, back_reading, vis[0]))
    return np.array(rows, dtype=float), [c.name for c in cameras]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene", type=Path)
    parser.add_argument("result", type=Path)
    parser.add_argument("--margin", type=float, default=0.2)
    parser.add_argument("--frames", help="also count these frames per view, e.g. 67-86")
    args = parser.parse_args(argv)
    rows, cameras = view_rows(args.scene, args.result)
    back, lies, reading, nose = rows[:, 2] > 0, rows[:, 3] > 0, rows[:, 4], rows[:, 5]
    reads_back, reads_front = reading > args.margin, reading < -args.margin
    print(f"{args.scene.name}: {len(rows)} view-frames, {back.sum()} see the back, the landmarks' sides swapped on "
          f"{lies.sum()}; nose visibility >= 0.95 on {(nose >= 0.95).sum()}")
    print(f"  read as a back: {reads_back.sum()}, of which fronts {(reads_back & ~back).sum()}, sides swapped "
          f"{(reads_back & lies).sum()}")
    print(f"  read as a front: {reads_front.sum()}, of which backs {(reads_front & back).sum()}, sides swapped "
          f"{(reads_front & lies).sum()}")
    if args.frames:
        first, last = (int(x) for x in args.frames.split("-"))
        for c, name in enumerate(cameras):
            sel = (rows[:, 0] >= first) & (rows[:, 0] <= last) & (rows[:, 1] == c)
            print(f"  frames {first}-{last}, {name}: {sel.sum()} frames, sees the back on {(sel & back).sum()}, "
                  f"sides swapped on {(sel & lies).sum()}, reads as a front on {(sel & (reading < 0)).sum()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
