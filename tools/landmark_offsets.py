"""Measure where BlazePose puts its landmarks relative to the rig's joints: the numbers behind
core/evidence/keypoints.py's LANDMARK_OFFSETS, and which bone should carry each landmark.

For every --step-th frame of each SCENE (a rendered capture with gt_joints.npz), the true pose is fitted to the
true joints, the landmark model runs on crops around it, the landmarks are triangulated over the views, and
each landmark's offset from its rig joint is expressed in the rest frame of a carrying bone, in units of the
rig's trunk, as (outwards for its side, forwards, up). Printed per landmark and per carrier ("own": the bone
LANDMARK_POINTS uses, the clavicle and pelvis bones for the shoulders and hips; "parent": that bone's parent):
the median over frames and both sides and the median absolute deviation around it. On walk and playground the
shoulder and hip offsets spread alike whether the upper arm and thigh or the trunk carry them (their arms
and legs swing little); with the arms crossed over the chest (busy) only the trunk keeps them on the landmarks.
The scenes disagree by up to 0.02 trunk (shoulders: walk -0.050 outwards, playground -0.028), more than the
median moves with the carrier: BlazePose's placement depends on the footage, which bounds what landmarks can
measure of a body's widths (docs/actor-calibration.md).

    .venv/bin/python tools/landmark_offsets.py sample_scenes/walk sample_scenes/playground [--step 2] [--raw]
        [--model heavy]

--raw: the offsets of the rig points without LANDMARK_OFFSETS (what the table should hold); without it, what is
left over with the table applied (close to zero when the table is right).
"""
import argparse
import sys
from pathlib import Path

import numpy as np


def measure(scene, step, raw, model="full"):
    """(landmark numbers (K,), {carrier: (F,K,3) offsets in trunk units, NaN where not triangulated})."""
    import bpy

    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.body.model import body_frame
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.crops import evidence_around
    from markerless_mocap.core.evidence.learned import LandmarkModel, model_path
    from markerless_mocap.core.evidence.keypoint_fit import triangulated_landmarks
    from markerless_mocap.core.evidence.keypoints import rig_keypoints
    from markerless_mocap.core.body.pose_fit import poses_from_joints
    from markerless_mocap.core.actor.landmark_fit import targets_from_landmarks
    from markerless_mocap.core.results.result_folder import load_joints

    bpy.ops.wm.open_mainfile(filepath=str(scene / "subject.blend"))
    body = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
    sk = body.skeleton
    rig = rig_keypoints(body, model)
    if raw:  # the joints themselves: the rest points without the table's offsets
        from markerless_mocap.core.evidence.keypoints import landmark_offsets

        rig.rest_points[:, :3] -= landmark_offsets(body, rig.landmarks, model)
    frame = body_frame(sk, body.roles)
    axes = np.stack([frame.left, frame.forward, frame.up])  # rest armature space -> (left, forward, up)
    neck, root = sk.index[body.roles["neck"][0]], sk.index[body.roles["root"][0]]
    trunk = np.linalg.norm(sk.rest[neck, :3, 3] - sk.rest[root, :3, 3])
    carriers = {"own": rig.bones, "parent": np.array([max(sk.parents[b], 0) for b in rig.bones])}
    names, frames, positions = load_joints(scene / "gt_joints.npz")
    picks = list(range(0, len(frames), step))
    poses, _ = poses_from_joints(body, names, positions[picks])
    capture = load_capture(scene)
    network = LandmarkModel(model_path(model))
    out = {c: [] for c in carriers}
    try:
        for pose, f in zip(poses, np.asarray(frames)[picks]):
            images = capture.frames.read(int(f))
            evidence = evidence_around(network, body, capture.cameras, [images[c.name] for c in capture.cameras],
                                       pose)  # as the tracker places the crops
            uv = np.stack([ev.keypoints for ev in evidence])
            vis = np.stack([ev.visibility if ev.found else np.zeros_like(ev.visibility) for ev in evidence])
            X, ok = triangulated_landmarks(capture.cameras, targets_from_landmarks(uv, vis, rig), rig)
            M = body.skinning_matrices(pose[None])[0]  # rest -> world per bone
            points = np.einsum("kij,kj->ki", M[rig.bones], rig.rest_points)[:, :3]
            for name, bones in carriers.items():
                R = M[bones, :3, :3]  # the carrier's rotation (rest -> world)
                rest_offset = np.einsum("kji,kj->ki", R, X - points)  # back into rest armature space
                out[name].append(np.where(ok[:, None], rest_offset @ axes.T / trunk, np.nan))
    finally:
        capture.close()
    side = np.where(rig.landmarks == _left_of_pair(rig.landmarks), 1.0, -1.0)
    result = {}
    for name, rows in out.items():
        a = np.array(rows)  # (F,K,3)
        a[..., 0] *= side  # outwards for the landmark's side
        result[name] = a
    return rig.landmarks, result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+", type=Path)
    ap.add_argument("--step", type=int, default=2)
    ap.add_argument("--raw", action="store_true", help="offsets from the joints (without LANDMARK_OFFSETS)")
    ap.add_argument("--model", default="full", help="the landmark model: full (LANDMARK_OFFSETS) or heavy "
                                                    "(HEAVY_LANDMARK_OFFSETS)")
    args = ap.parse_args(argv)
    merged = {}
    for scene in args.scenes:
        landmarks, result = measure(scene, args.step, args.raw, args.model)
        for name, a in result.items():
            merged.setdefault(name, []).append(a)
            print(f"{scene.name}, carrier {name}: median (outwards, forwards, up) / MAD, trunk units")
            _print(medians(landmarks, a))
    for name, arrays in merged.items():
        print(f"all scenes, carrier {name}:")
        _print(medians(landmarks, np.concatenate(arrays)))


def medians(landmarks, offsets):
    """{left landmark number: (median (3,), median absolute deviation (3,), count)} over frames and both
    sides; offsets (F,K,3) as `measure` returns them (NaN where a landmark did not triangulate)."""
    pairs = {}
    for k, lm in enumerate(landmarks):
        pairs.setdefault(int(_left_of_pair(lm)), []).append(offsets[:, k])
    out = {}
    for key, cols in sorted(pairs.items()):
        v = np.concatenate(cols)
        v = v[np.isfinite(v).all(axis=1)]
        med = np.median(v, axis=0)
        out[key] = (med, np.median(np.abs(v - med), axis=0), len(v))
    return out


def _left_of_pair(landmarks):
    """The left landmark's number of each landmark's left/right pair (itself for the nose): the lower of the
    two in BlazePose's numbering, as SWAP_ORDER pairs them."""
    from markerless_mocap.core.evidence.learned import SWAP_ORDER

    return np.minimum(landmarks, SWAP_ORDER[landmarks])


def _print(table):
    for key, (med, mad, n) in table.items():
        print(f"  {key:2d}: ({med[0]:+.3f}, {med[1]:+.3f}, {med[2]:+.3f})  MAD ({mad[0]:.3f}, {mad[1]:.3f}, "
              f"{mad[2]:.3f})  n={n}")


if __name__ == "__main__":
    sys.exit(main())
