"""How alike the clothes under a take's landmarks are to the actor's of its first frames, per frame and view
(core/evidence/appearance.py): the figure the tracker's check by clothes compares with its threshold.

For every frame of RESULT (a result folder, its keypoints.npz: the landmarks the take was solved with) the
signature under each view's landmarks is scored against the signatures of the first --learn frames (every view);
with --truth and --other (the actor's and the other person's joints) each view's landmarks are also said to be the
actor's (A) or the other's (B), by which person's projected hips and shoulders they lie nearer.

    .venv/bin/python tools/clothes_likeness.py CAPTURE RESULT [--truth T.npz --other O.npz] [--learn 3]

docs/measurements.md, "Other people in the room" ("Told apart by their clothes"), quotes it.
"""
import argparse
from pathlib import Path

import numpy as np

TRUNK_JOINTS = ("LeftArm", "RightArm", "LeftUpLeg", "RightUpLeg")
TRUNK_LANDMARKS = (11, 12, 23, 24)


def main(argv=None):
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.appearance import clothes_signature, likeness
    from markerless_mocap.core.results.result_folder import load_joints

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("result", type=Path)
    ap.add_argument("--truth", type=Path)
    ap.add_argument("--other", type=Path)
    ap.add_argument("--learn", type=int, default=3)
    ap.add_argument("--min-visibility", type=float, default=0.5)
    args = ap.parse_args(argv)

    capture = load_capture(args.capture)
    cameras = capture.cameras
    with np.load(args.result / "keypoints.npz") as saved:
        order = [list(saved["cameras"]).index(c.name) for c in cameras]
        uv, vis, frames = saved["uv"][:, order], saved["visibility"][:, order], saved["frames"]
    people = []
    for path in (args.truth, args.other):
        if path is not None:
            names, tf, pos = load_joints(path)
            idx = [list(names).index(n) for n in TRUNK_JOINTS]
            people.append({int(f): pos[i][idx] for i, f in enumerate(tf)})

    exemplars, rows = [], []
    for i, frame in enumerate(frames):
        images = capture.frames.read(int(frame))
        sigs = [clothes_signature(images[c.name], uv[i, k], vis[i, k] >= args.min_visibility)
                for k, c in enumerate(cameras)]
        if i < args.learn:
            exemplars += [s for s in sigs if s]
            continue
        for k, c in enumerate(cameras):
            who = "-"
            if len(people) == 2:
                lm = uv[i, k][list(TRUNK_LANDMARKS)]
                d = [np.linalg.norm(c.project(p[int(frame)]) - lm, axis=1).mean() for p in people]
                who = "A" if d[0] <= d[1] else "B"
            rows.append((int(frame), c.name, likeness(sigs[k], exemplars), who))
    capture.close()

    print("frame " + " ".join(f"{c.name:>10}" for c in cameras))
    by_frame = {}
    for frame, cam, like, who in rows:
        by_frame.setdefault(frame, {})[cam] = (like, who)
    for frame, views in by_frame.items():
        cells = []
        for c in cameras:
            like, who = views.get(c.name, (None, "-"))
            cells.append(f"{'   -' if like is None else f'{like:.3f}'} {who}".rjust(10))
        print(f"{frame:5d} " + " ".join(cells))
    for who in sorted({r[3] for r in rows}):
        vals = np.array([r[2] for r in rows if r[3] == who and r[2] is not None])
        if len(vals):
            print(f"{who}: {len(vals)} views, likeness min {vals.min():.3f}, 5 % {np.percentile(vals, 5):.3f}, "
                  f"median {np.median(vals):.3f}, max {vals.max():.3f}")


if __name__ == "__main__":
    main()
