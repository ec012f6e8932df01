"""Foot locking: planted feet held still on the floor by refitting the legs of a finished take.

For each contact (core/tracking/foot_contact.py) the planted point is held where the take puts it on average over
the contact, along the floor; its height stays the take's (a heel rising as the step rolls onto the toes is
motion, not slide). The correction a contact needs fades in and out over BLEND_FRAMES frames on either side,
so the foot does not jump. On every frame, a contact point below the floor is raised towards it. The leg's DOFs
(hip, knee, ankle) are then refitted by least squares so its foot points reach their targets while its knee stays
near the take's (KNEE_HOLD), starting from the take's pose (core/evidence/keypoint_fit.py, fit_to_points); the
rest of the body is not touched.

The tracker's evidence still has the last word: a contact whose pinning would move the leg's joints farther than
MAX_LEG_SHIFT from where the take has them (beyond what raising the foot onto the floor asks) is not held still. It
is held on its own smoothed path instead (a moving average over FOLLOW_FRAMES frames): a seated person's foot that
shuffles or a stance that drifts keeps its drift and loses only the frame-to-frame jitter. A contact that even this
moves too far is left as tracked.
Measured against the images' own evidence (docs/defaults.md, "MAX_LEG_SHIFT"): within it, the pinned legs reproject
onto the learned landmarks as well as the take's do.
"""
from __future__ import annotations

import numpy as np

from .foot_contact import CONTACT_HEIGHT, CONTACT_SPEED, detect_contacts, feet, fit_floor

# Frames over which a contact's correction fades in before it and out after it (docs/defaults.md, "BLEND_FRAMES").
BLEND_FRAMES = 3
# A pinning that moves a leg joint farther than this from the take (metres, the floor's lift apart) is not taken
# (docs/defaults.md, "MAX_LEG_SHIFT").
MAX_LEG_SHIFT = 0.015
MOVED = 1e-5  # a frame whose targets are this close to the take keeps its pose (metres)
# A contact that cannot be held still follows its path averaged over this many frames (docs/defaults.md,
# "FOLLOW_FRAMES"); None leaves it as tracked.
FOLLOW_FRAMES = 9


# The refit also holds the knee where the take has it, its distance weighted this much against the foot points':
# a sunk foot is raised by bending the knee and ankle, not by swinging the thigh, and where that cannot reach the
# floor it stays a few mm under it (docs/defaults.md, "KNEE_HOLD").
KNEE_HOLD = 0.5


class _Heads:
    """The bone heads `fit_to_points` moves onto their targets (its rig_points interface), each scaled by its
    weight (the targets are scaled alike, so a weight scales that head's residual)."""

    def __init__(self, bones, weights):
        self.bones = np.asarray(bones, dtype=np.int64)
        self.weights = np.asarray(weights, dtype=np.float64)

    def world(self, body, poses):
        return body.joint_positions(np.atleast_2d(poses))[:, self.bones] * self.weights[:, None]


def _fade(n):
    """Weights of the n frames next to a contact, from near 1 beside it to near 0 (a half cosine)."""
    return 0.5 * (1 + np.cos(np.pi * np.arange(1, n + 1) / (n + 1)))


def _tangential(p, normal):
    return p - (p @ normal)[..., None] * normal


def smoothed_path(points, window):
    """(n,3) points averaged over `window` frames centred on each (the window shrinks at the ends)."""
    half = window // 2
    c = np.vstack([np.zeros((1, points.shape[1])), np.cumsum(points, axis=0)])
    lo = np.maximum(np.arange(len(points)) - half, 0)
    hi = np.minimum(np.arange(len(points)) + half + 1, len(points))
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def corrections(joints, foot_list, contacts, floor, frames, blend=BLEND_FRAMES, following=()):
    """(F, n_feet, n_points, 3) displacement along the floor that pins each contact, faded in and out around it;
    the contacts in `following` are moved onto their smoothed path (FOLLOW_FRAMES) instead of held still."""
    F = len(joints)
    n_pts = max(len(f.points) for f in foot_list)
    out = np.zeros((F, len(foot_list), n_pts, 3))
    inside = np.zeros((F, len(foot_list), n_pts), bool)
    breaks = np.r_[0, np.flatnonzero(np.diff(frames) != 1) + 1, F]
    for c in contacts:
        p = joints[c.first:c.stop, foot_list[c.foot].points[c.point]]
        tan = _tangential(p, floor.normal)
        held = smoothed_path(tan, FOLLOW_FRAMES) if c in following else tan.mean(axis=0)
        out[c.first:c.stop, c.foot, c.point] = held - tan
        inside[c.first:c.stop, c.foot, c.point] = True
    faded = out.copy()
    for c in contacts:
        run_start = breaks[breaks <= c.first].max()
        run_stop = breaks[breaks > c.first].min()
        w = _fade(blend)
        for k in range(blend):  # before the contact, then after it; never into another contact or another run
            for t, edge in ((c.first - 1 - k, c.first), (c.stop + k, c.stop - 1)):
                if run_start <= t < run_stop and not inside[t, c.foot, c.point]:
                    faded[t, c.foot, c.point] += w[k] * out[edge, c.foot, c.point]
    return faded


def _targets(joints, foot, k, shift, floor):
    """(F, n_points, 3) targets of one foot's points: moved by its own correction where it has one, else by the
    foot's other point's (the foot moves as one), then raised onto the floor."""
    n = len(foot.points)
    own = shift[:, k, :n]
    has = np.linalg.norm(own, axis=-1) > 0  # (F,n)
    move = own.copy()
    for j in range(n):
        for other in range(n):  # a point without a contact moves with one that has
            borrow = ~has[:, j] & has[:, other]
            move[borrow, j] = own[borrow, other]
    target = joints[:, foot.points] + move
    below = foot.clearance[None] - floor.height(target)  # how far each point is under the floor
    lift = np.max(np.maximum(below, 0.0), axis=1)  # raise the foot by its lowest point's depth
    return target + lift[:, None, None] * floor.normal, lift


def _refit(body, poses, foot, targets, joints, fit_max_nfev=30):
    """The leg's DOFs refitted per frame so its foot points reach `targets` (F,n,3) where they moved."""
    from ..evidence.keypoint_fit import fit_to_points

    out = poses.copy()
    heads = _Heads(np.r_[foot.points, foot.knee], np.r_[np.ones(len(foot.points)), KNEE_HOLD])
    moved = np.linalg.norm(targets - joints[:, foot.points], axis=-1).max(axis=1) > MOVED
    ok = np.ones(len(foot.points) + 1, bool)
    for t in np.flatnonzero(moved):
        aims = np.vstack([targets[t], KNEE_HOLD * joints[t, foot.knee]])
        out[t], _ = fit_to_points(body, heads, poses[t], aims, ok, dofs=foot.leg_dofs, max_nfev=fit_max_nfev)
    return out


def lock_feet(body, poses, frames, fps, height=CONTACT_HEIGHT, speed=CONTACT_SPEED, floor=None,
              max_shift=MAX_LEG_SHIFT, blend=BLEND_FRAMES):
    """A finished take's poses (F,D) of `frames` (F,) at `fps` -> (poses with the feet locked, a report dict for
    report.json: the floor used, the contacts pinned and those left as tracked)."""
    poses = np.asarray(poses, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.int64)
    foot_list = feet(body)
    joints = body.joint_positions(poses)
    floor = fit_floor(joints, foot_list, fps, speed) if floor is None else floor
    contacts = detect_contacts(joints, foot_list, floor, fps, frames, height, speed)
    out = poses.copy()
    kept, rejected, followed = [], [], []
    for k, foot in enumerate(foot_list):  # the legs are refitted apart: each moves only its own foot
        mine = [c for c in contacts if c.foot == k]
        following = []
        while True:  # contacts whose pinning moves the leg too far follow their path, then are dropped
            shift = corrections(joints, foot_list, mine, floor, frames, blend, following)
            targets, lift = _targets(joints, foot, k, shift, floor)
            leg = _refit(body, poses, foot, targets, joints)
            moved = body.joint_positions(leg)[:, foot.leg_bones]
            distance = np.linalg.norm(moved - joints[:, foot.leg_bones], axis=-1).max(axis=1) - lift
            too_far = [c for c in mine
                       if np.any(distance[max(c.first - blend, 0):c.stop + blend] > max_shift)]
            if not too_far:
                break
            dropped = [c for c in too_far if c in following or FOLLOW_FRAMES is None]
            following = [c for c in following if c not in dropped] + [c for c in too_far if c not in dropped]
            rejected += dropped
            mine = [c for c in mine if c not in dropped]
        kept += [c for c in mine if c not in following]
        followed += following
        out[:, foot.leg_dofs] = leg[:, foot.leg_dofs]
    report = {
        "floor": floor.to_dict(),
        "contact_height_m": float(height), "contact_speed_m_s": float(speed), "max_leg_shift_m": float(max_shift),
        "blend_frames": int(blend),
        "clearance_m": {name: round(float(c), 4) for f in foot_list for name, c in zip(f.names, f.clearance)},
        "contacts": [c.to_dict(foot_list, frames) for c in kept],
        "following_their_path": [c.to_dict(foot_list, frames) for c in followed], "follow_frames": FOLLOW_FRAMES,
        "left_as_tracked": [c.to_dict(foot_list, frames) for c in rejected],
    }
    return out, report


__all__ = ["BLEND_FRAMES", "FOLLOW_FRAMES", "KNEE_HOLD", "MAX_LEG_SHIFT", "corrections", "lock_feet", "smoothed_path"]
