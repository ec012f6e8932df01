"""Measure how the learned landmarks misstate segment lengths: fit proportions to a result folder whose actor
IS the subject (the bundled walk and playground scenes), and print fitted / true per segment (1.000 = exact).
Measured (40 frames, seed 0): the ratios depend on the motion (forearm 0.94 on walk, 1.00 on playground; hip
width 0.92 / 1.02), so no fixed correction is applied; see README, "Actor calibration".

    .venv/bin/python tools/landmark_length_bias.py RESULT:SCENE [RESULT:SCENE ...] [--frames N]

RESULT: a `track` result folder (keypoints.npz, poses.npz) of SCENE (a capture folder with subject.blend).
"""
import argparse
import sys
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="+")
    ap.add_argument("--frames", type=int, default=40, help="the first N frames of each result")
    args = ap.parse_args(argv)
    import bpy

    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.capture.calibration import read_calibration
    from markerless_mocap.core.proportions import SEGMENTS
    from markerless_mocap.core.proportions_fit import fit_proportions

    ratios = []
    for pair in args.pairs:
        result, scene = (Path(p) for p in pair.split(":"))
        bpy.ops.wm.open_mainfile(filepath=str(scene / "subject.blend"))
        body = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
        with np.load(result / "keypoints.npz") as z:
            uv, vis, frames = z["uv"][:args.frames], z["visibility"][:args.frames], z["frames"][:args.frames]
        with np.load(result / "poses.npz") as z:
            poses = z["poses"][:args.frames]
        fit = fit_proportions(body, read_calibration(scene), uv, vis, poses, frames=frames)
        r = {s: fit.lengths[s] / fit.subject_lengths[s] for s in SEGMENTS}
        ratios.append(r)
        print(scene.name, " ".join(f"{s} {v:.3f}" for s, v in r.items()))
    mean = {s: float(np.mean([r[s] for r in ratios])) for s in SEGMENTS}
    print("mean", " ".join(f"{s} {v:.3f}" for s, v in mean.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
