"""Chunks back into one take: each chunk's kept frames, cross-faded with the previous chunk over the overlap.

In the overlap the pose goes from the earlier chunk's to the later one's with t = (j + 1) / (O + 1) at the j-th
shared frame, so the take has no step at either end of it: the root translation linearly, the root orientation
along the shortest arc (slerp), and every bone's own rotation along the shortest arc too, the joint angles solved
for the bone rotations that arc passes through (an angle per axis is not a point on the sphere: two interpolated
axis angles of one bone leave the arc when the bone turns about several axes). The whole take is smoothed
afterwards as one (core/tracking/smoothing.py), by the caller.

How far the two chunks disagree where both are settled is a quality figure of the stitch: mean and largest distance
of the 15 evaluation joints (core/results/evaluation.py) over the overlap, in millimetres.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..body.rotations import matrix_to_rotvec, quaternions_to_rotvecs, rotvec_to_matrix, rotvecs_to_quaternions
from ..results.evaluation import EvaluationError, joint_indices
from .chunk_folder import ChunkError

_FIT_STEP = 1e-6  # radians: the finite difference of the joint-angle fit's Jacobian
_FIT_TOLERANCE = 1e-12  # squared radians: bone rotations this close to the arc are on it
_FIT_ITERATIONS = 8


def _arc(ra, rb, t):
    """(...,3,3) rotations a fraction t along the shortest arc from ra to rb."""
    return ra @ rotvec_to_matrix(t * matrix_to_rotvec(np.swapaxes(ra, -1, -2) @ rb))


def _angle_bones(body):
    """(angle DOF indices, the bones they turn) of the body, the root bone left out."""
    angles = np.array([i for i, d in enumerate(body.dofs) if d.kind == "angle"], dtype=np.int64)
    bones = sorted({t.bone for i in angles for t in body.dofs[i].targets} - {body.root_bone})
    return angles, np.array(bones, dtype=np.int64)


def blend_poses(body, a, b, t):
    """The pose a fraction t (0..1) of the way from pose a to pose b (D,) on the sphere (see the module's text)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    t = float(t)
    x = (1.0 - t) * a + t * b
    rot = body.root_rotation_dofs
    if rot.size:
        arc = _arc(rotvec_to_matrix(a[rot]), rotvec_to_matrix(b[rot]), t)
        q = rotvecs_to_quaternions(matrix_to_rotvec(arc)[None])
        x[rot] = quaternions_to_rotvecs(q, x[rot][None])[0]
    angles, bones = _angle_bones(body)
    if angles.size == 0 or t <= 0.0 or t >= 1.0:
        return body.clamp(x) if 0.0 < t < 1.0 else (a.copy() if t <= 0.0 else b.copy())
    ends = body.local_bases(np.stack([a, b]))[:, bones, :3, :3]
    target = _arc(ends[0], ends[1], t)
    target_t = np.swapaxes(target, -1, -2)

    def residuals(values):
        """(P, angles) -> (P, bones * 3): each bone's rotation away from the arc's, as rotation vectors."""
        poses = np.repeat(x[None], len(values), axis=0)
        poses[:, angles] = values
        rotations = body.local_bases(poses)[:, bones, :3, :3]
        return matrix_to_rotvec(target_t[None] @ rotations).reshape(len(values), -1)

    v = x[angles].copy()  # Gauss-Newton from the angles' linear blend, which is the answer for one-axis bones
    for _ in range(_FIT_ITERATIONS):
        trial = np.vstack([v, v + _FIT_STEP * np.eye(len(v))])
        r = residuals(trial)
        if r[0] @ r[0] < _FIT_TOLERANCE:
            break
        jac = (r[1:] - r[0]).T / _FIT_STEP
        v = v - np.linalg.lstsq(jac, r[0], rcond=None)[0]
    x[angles] = v
    return body.clamp(x)


def _eval_joints(body):
    try:
        return joint_indices(list(body.skeleton.bone_names), "the subject")
    except EvaluationError:  # a rig without the 15 joints' bones: every bone head
        return np.arange(body.skeleton.n_bones)


def _needed(chunk, estimates, frames):
    missing = [f for f in frames if f not in estimates]
    if missing:
        raise ChunkError(f"chunk {chunk.index} (frames {chunk.track[0]}-{chunk.track[1]}) lacks frames "
                         f"{missing[0]}-{missing[-1]}: delete its folder and track it again")


def stitch(body, chunks, estimates):
    """The take's FrameEstimates from its chunks (core/batch/plan.py) and each chunk's {frame: FrameEstimate},
    with a report: per overlap the frames and the joints' mean / largest disagreement (mm), and per chunk boundary
    the disagreement at every frame both chunks tracked (the later one's warm-up included: how it settled)."""
    joints = _eval_joints(body)
    out, overlaps = [], []
    for i, chunk in enumerate(chunks):
        mine = estimates[i]
        _needed(chunk, mine, range(chunk.track[0], chunk.track[1] + 1))
        shared = None
        if i > 0:
            before = estimates[i - 1]
            both = [f for f in range(chunk.track[0], chunks[i - 1].track[1] + 1)]
            gaps = [float(np.linalg.norm(before[f].joints[joints] - mine[f].joints[joints], axis=1).mean() * 1e3)
                    for f in both]
            shared = {"frames": [both[0], both[-1]] if both else None, "mean_joint_mm": [round(g, 2) for g in gaps]}
        faded = []
        for f in range(chunk.keep[0], chunk.keep[1] + 1):
            est = mine[f]
            j = f - chunk.keep[0]
            if j < chunk.fade_in:
                earlier = estimates[i - 1][f]
                pose = blend_poses(body, earlier.pose, est.pose, (j + 1) / (chunk.fade_in + 1))
                faded.append(np.linalg.norm(earlier.joints[joints] - est.joints[joints], axis=1))
                est = dataclasses.replace(est, pose=pose, joints=body.joint_positions(pose[None])[0])
            out.append(est)
        if i > 0:
            gap = np.concatenate(faded) * 1e3 if faded else None
            overlaps.append({"chunks": [i - 1, i], "frames": [chunk.keep[0], chunk.keep[0] + chunk.fade_in - 1]
                             if chunk.fade_in else None,
                             "mean_joint_mm": None if gap is None else round(float(gap.mean()), 2),
                             "max_joint_mm": None if gap is None else round(float(gap.max()), 2),
                             "shared": shared})
    return out, overlaps


__all__ = ["blend_poses", "stitch"]
