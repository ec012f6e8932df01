"""Measure how the learned landmarks, and the silhouette refinement after them, misstate segment lengths: fit
proportions to a result folder of a scene whose actor's lengths are known (the subject's own for walk,
playground and the other bundled scenes; scene_info.json > actor > true_segment_lengths_m for the actor
scene), and print fitted / true per segment (1.000 = exact), landmarks alone and refined against the person
masks.
Measured (seed 0): the landmark ratios depend on the motion (forearm 0.94 on walk, 1.00 on playground; hip
width 0.92 / 1.02), so no fixed correction is applied; the masks bring the forearm and hip width within a
few per cent on both; see docs/actor-calibration.md.

    .venv/bin/python tools/landmark_length_bias.py RESULT:SCENE [RESULT:SCENE ...] [--frames N]
        [--all-segments | --segments forearm,hip_width,...]

RESULT: a `track` or `calibrate` result folder (keypoints.npz, poses.npz; for calibrate, its
calibration_frames/) of SCENE (a capture folder with subject.blend).

"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="+")
    ap.add_argument("--frames", type=int, default=40, help="the first N frames of each result")
    ap.add_argument("--all-segments", action="store_true",
                    help="let the masks refine every segment (default: those the calibration refines)")
    ap.add_argument("--segments", help="comma-separated segments the masks refine (overrides --all-segments)")
    ap.add_argument("--backend", default="fast")
    args = ap.parse_args(argv)
    import bpy

    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.capture.calibration import read_calibration
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.actor.proportions import SEGMENTS
    from markerless_mocap.core.actor.landmark_fit import fit_proportions
    from markerless_mocap.core.actor.silhouette_fit import SILHOUETTE_SEGMENTS, refine_fit
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.core.tracking.tracker import Tracker

    segments = SEGMENTS if args.all_segments else SILHOUETTE_SEGMENTS
    if args.segments:
        segments = tuple(args.segments.split(","))
    ratios, refined_ratios = [], []
    for pair in args.pairs:
        result, scene = (Path(p) for p in pair.split(":"))
        bpy.ops.wm.open_mainfile(filepath=str(scene / "subject.blend"))
        body = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
        with np.load(result / "keypoints.npz") as z:
            uv, vis, frames = z["uv"][:args.frames], z["visibility"][:args.frames], z["frames"][:args.frames]
        with np.load(result / "poses.npz") as z:
            poses = z["poses"][:args.frames]
        fit = fit_proportions(body, read_calibration(scene), uv, vis, poses, frames=frames)
        true = true_lengths(scene, fit.subject_lengths)
        r = {s: fit.lengths[s] / true[s] for s in SEGMENTS}
        ratios.append(r)
        print(scene.name, "landmarks  ", " ".join(f"{s} {v:.3f}" for s, v in r.items()))
        capture = load_capture(scene)
        try:
            tracker = Tracker(body, capture, TrackingSettings(backend=args.backend))
            used = [list(frames).index(f) for f in fit.frames]
            refined = refine_fit(fit, body, tracker, uv[used], vis[used], segments=segments)
        finally:
            capture.close()
        r = {s: refined.lengths[s] / true[s] for s in SEGMENTS}
        refined_ratios.append(r)
        print(scene.name, "silhouettes", " ".join(f"{s} {v:.3f}" for s, v in r.items()))
    for name, rs in (("landmarks  ", ratios), ("silhouettes", refined_ratios)):
        mean = {s: float(np.mean([r[s] for r in rs])) for s in SEGMENTS}
        print("mean", name, " ".join(f"{s} {v:.3f}" for s, v in mean.items()))
    return 0


def true_lengths(scene, subject_lengths):
    """The actor's segment lengths: scene_info.json's when the scene was rendered with another body, else the
    subject's own."""
    info = scene / "scene_info.json"
    if info.is_file():
        actor = json.loads(info.read_text()).get("actor", {})
        if "true_segment_lengths_m" in actor:
            return actor["true_segment_lengths_m"]
    return subject_lengths


if __name__ == "__main__":
    sys.exit(main())
