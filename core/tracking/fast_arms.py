"""Fast arms keep their solved poses through smoothing.

A low-pass at DEFAULT_CUTOFF_HZ removes the frame-to-frame jitter of a solved take, but a hand flung at 6-12 m/s
crosses 20-40 cm per frame: the filter averages those positions and the smoothed wrist cuts the corner by 10 cm
and more. Each arm is therefore faded from its smoothed to its solved angles where its wrist moves fast about its
shoulder (measured on the smoothed take): not at all below FAST_ARM_FROM, fully from FAST_ARM_TO. The speed is
taken between the frame's two neighbours, so that a lost arm jumping back and forth between wrong places does not
read as fast. Slow arms, the trunk and the legs stay smoothed. docs/defaults.md, "FAST_ARM_FROM" holds the
measurements behind both speeds.
"""
from __future__ import annotations

import numpy as np

from .frame_runs import consecutive_runs

FAST_ARM_FROM = 3.0  # m/s of the wrist about its shoulder: the arm starts to keep its solved angles
FAST_ARM_TO = 6.0    # m/s: the arm keeps its solved angles fully


def arms(body):
    """[(side, shoulder bone, wrist bone, the arm's DOF indices)] of the arms `body` has (a rig without an arm's
    shoulder and elbow roles, or without a hand bone after the forearm, has none for that side)."""
    from ..evidence.keypoints import KeypointMapError, end_bone

    roles = getattr(body, "roles", None) or {}
    out = []
    for side in "lr":
        shoulder, elbow = f"{side}_shoulder", f"{side}_elbow"
        if shoulder not in roles or elbow not in roles:
            continue
        try:
            wrist = int(end_bone(body, elbow))
        except KeypointMapError:
            continue
        dofs = np.array([i for i, d in enumerate(body.dofs) if d.role in (shoulder, elbow)], dtype=np.int64)
        if dofs.size:
            out.append((side, body.skeleton.index[roles[shoulder][0]], wrist, dofs))
    return out


def fast_weights(wrist_about_shoulder, frames, fps):
    """Per frame, how much of the solved angles an arm keeps (0-1), from its wrist's positions about the shoulder
    (F, 3) in metres. The speed of frame k is the distance from frame k-1 to k+1 over two frame times (at the ends
    of a run of consecutive frames, the one step there is); a gap in the frame numbers is not a step."""
    frames = np.asarray(frames)
    path = np.asarray(wrist_about_shoulder, dtype=np.float64)
    speed = np.zeros(len(frames))
    for start, stop in consecutive_runs(frames):
        if stop - start < 2:
            continue
        run = path[start:stop]
        before = np.r_[0, np.arange(stop - start - 1)]  # each frame's previous frame in the run (itself at the start)
        after = np.r_[np.arange(1, stop - start), stop - start - 1]
        speed[start:stop] = (np.linalg.norm(run[after] - run[before], axis=-1) * float(fps)
                             / np.maximum(after - before, 1))
    return np.clip((speed - FAST_ARM_FROM) / (FAST_ARM_TO - FAST_ARM_FROM), 0.0, 1.0)


def keep_fast_arms(body, solved, smoothed, frames, fps):
    """`smoothed` (F, D) with each arm's angles faded towards `solved` where its wrist moves fast."""
    out = np.array(smoothed, dtype=np.float64)
    sides = arms(body)
    if not sides:
        return out
    joints = body.joint_positions(out)
    for _side, shoulder, wrist, dofs in sides:
        w = fast_weights(joints[:, wrist] - joints[:, shoulder], frames, fps)[:, None]
        out[:, dofs] = (1.0 - w) * out[:, dofs] + w * np.asarray(solved)[:, dofs]
    return out
