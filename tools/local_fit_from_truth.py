"""Search failure or energy failure? At chosen frames of a result on a rendered scene: the energy of the
tracked pose and of the true pose, and where the local fit (the ICP step after the search) goes when it starts
AT the true pose.

The true pose is the rig fitted to the true joints over the whole clip up to the last frame asked for, each frame
warm-started from the one before (core/body/pose_fit.poses_from_joints). Fitting single frames from the rest pose
is not enough: with the arms crossed (busy, frames 34-44) such fits land 0.1-0.3 m off on the crossed arm, and
energies compared at them blame the energy wrongly (an earlier diagnosis was built on that; docs/measurements.md, busy).

If the truth costs less than the tracked pose and the local fit stays there, the search missed it; if the truth
costs more, or the local fit walks away from it, the energy's minimum is elsewhere. The local fit is repeated
without the keypoints and without the prior, to see which term pulls.

    .venv/bin/python tools/local_fit_from_truth.py sample_scenes/busy RESULT 34,38,40,44 [--seed 0]
"""
import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", type=Path, help="a rendered sample scene (subject.blend, gt_joints.npz)")
    ap.add_argument("result", type=Path, help="a track result folder of that scene")
    ap.add_argument("frames", help="capture frames, comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    frames = [int(f) for f in args.frames.split(",")]

    from markerless_mocap.addon.scene_bridge import find_armature
    from markerless_mocap.core.results.evaluation import EVAL_JOINTS
    from markerless_mocap.core.energy.likelihood import default_pose_at
    from markerless_mocap.core.optimizers import icp
    from markerless_mocap.core.body.pose_fit import poses_from_joints
    from markerless_mocap.core.results.result_folder import ResultWriter, load_joints
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.operators.cmd_track import open_subject
    from markerless_mocap.operators.track_session import TrackSession

    scene = open_subject(args.scene / "subject.blend")
    session = TrackSession(scene, find_armature(scene), args.scene, args.result / "local_fit_from_truth",
                           TrackingSettings(seed=args.seed), smooth_hz=0)
    tracker, body = session.prepare(), session.body
    names, truth_frames, positions = load_joints(args.scene / "gt_joints.npz")
    last = int(np.searchsorted(truth_frames, max(frames)))
    truth_poses, _ = poses_from_joints(body, names, positions[:last + 1])
    raw_poses = args.result / ResultWriter.RAW_FILES[1]  # the take as solved, when the result was smoothed
    solved = np.load(raw_poses if raw_poses.is_file() else args.result / "poses.npz")
    joints = [c[0] for c in EVAL_JOINTS.values()]
    bones = [body.skeleton.index[b] for b in joints]
    columns = [names.index(b) for b in joints]

    def errors(pose, frame):
        """Mean error and the worst joint of `pose` against the true joints (mm)."""
        J = body.joint_positions(pose[None])[0, bones]
        e = 1000 * np.linalg.norm(J - positions[list(truth_frames).index(frame), columns], axis=1)
        worst = int(np.argmax(e))
        return f"{e.mean():.0f} mm (worst {list(EVAL_JOINTS)[worst]} {e[worst]:.0f})"

    tracker.energy.set_reference_pose(default_pose_at(body, truth_poses[0]))
    weights = tracker.energy.weights
    base_settings = icp.IcpSettings
    variants = {"": {}, "without keypoints": {"keypoint_weight": 0.0}, "without the prior": {"prior_weight": 0.0}}
    try:
        for frame in frames:
            tracked = solved["poses"][list(solved["frames"]).index(frame)]
            truth = truth_poses[list(truth_frames).index(frame)]
            tracker.anchor = np.eye(3)
            tracker.load_frame(frame, guide_poses=tracked[None])
            terms = tracker.energy.terms(np.stack([tracked, truth]))
            split = ", ".join(f"{n} {getattr(weights, n) * v[0]:.2f}/{getattr(weights, n) * v[1]:.2f}"
                              for n, v in terms.items())
            total = tracker.energy(np.stack([tracked, truth]))
            print(f"frame {frame}: energy tracked {total[0]:.2f}, truth {total[1]:.2f} ({split}); "
                  f"error tracked {errors(tracked, frame)}, truth fit {errors(truth, frame)}")
            for label, change in variants.items():
                icp.IcpSettings = lambda *a, change=change, **k: dataclasses.replace(base_settings(*a, **k), **change)
                fitted = tracker.to_absolute(tracker.fit_locally(tracker.to_relative(truth)))
                icp.IcpSettings = base_settings
                print(f"   local fit from the truth{' ' + label if label else ''}: energy "
                      f"{float(tracker.energy(fitted[None])[0]):.2f}, error {errors(fitted, frame)}")
    finally:
        icp.IcpSettings = base_settings
        tracker.finish_prefetch()
        session.capture.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
