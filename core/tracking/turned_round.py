"""The body turned round: the pose that faces the other way yet casts nearly the same pictures.

Front and back look alike to the silhouettes and the edges, and the landmark term lets each view swap left and
right (single-view landmark models often call a back a front), so a body that falls behind a fast turn can
settle facing backwards with its limbs exchanged: the person's reflection through their own frontal plane
(docs/measurements.md, "Turned round"). No small step leads back from there. This module builds that
reflection of a pose; the tracker fits it locally and keeps it where it explains the images better.
"""
from __future__ import annotations

import re

import numpy as np

from ..body.pose_fit import fit_pose, initial_root

_SIDES = {"Left": "Right", "Right": "Left", "left": "right", "right": "left"}


def mirror_name(name):
    """A bone's left/right partner's name by the usual conventions (LeftArm, LHipJoint, mixamorig:LeftHand, arm.L,
    arm_l); the name itself when it names no side."""
    swapped = re.sub("Left|Right|left|right", lambda m: _SIDES[m.group(0)], name)
    if swapped != name:
        return swapped
    swapped = re.sub(r"(^|[:_.])([LR])(?=[A-Z])", lambda m: m.group(1) + ("R" if m.group(2) == "L" else "L"), name)
    if swapped != name:
        return swapped
    return re.sub(r"([._])([LRlr])$", lambda m: m.group(1) + {"L": "R", "R": "L", "l": "r", "r": "l"}[m.group(2)],
                  name)


def mirror_partners(bone_names):
    """(B,) the index of each bone's left/right partner (itself for a central bone or one without a partner)."""
    where = {n: i for i, n in enumerate(bone_names)}
    return np.array([where.get(mirror_name(n), i) for i, n in enumerate(bone_names)])


def frontal_normal(body, heads):
    """The horizontal unit vector the body faces along (its frontal plane's normal), from the hips and shoulders."""
    index = body.skeleton.index
    point = {role: heads[index[body.roles[role][0]]] for role in ("l_hip", "r_hip", "l_shoulder", "r_shoulder")}
    across = point["l_hip"] - point["r_hip"] + point["l_shoulder"] - point["r_shoulder"]
    across[2] = 0.0
    normal = np.array([across[1], -across[0], 0.0])  # perpendicular to across in the floor plane
    length = np.linalg.norm(normal)
    return normal / length if length > 1e-9 else None


class TurnedRound:
    """The reflection of poses through their frontal plane, fitted back into the body's DOFs."""

    TEST_ANGLE = 0.3  # rad: the angle each DOF is turned by to find its partner's sign

    def __init__(self, body):
        self.body = body
        self.partners = mirror_partners(body.skeleton.bone_names)
        self.dof_partner, self.dof_sign = self._mirrored_dofs()

    def _reflect(self, heads):
        normal = frontal_normal(self.body, heads)
        if normal is None:
            return None
        centre = heads[self.body.root_bone]
        return (heads - 2.0 * ((heads - centre) @ normal)[:, None] * normal[None])[self.partners]

    def _mirrored_dofs(self):
        """Each joint angle's partner (l_ <-> r_, itself for the spine and neck) and the sign that mirrors it,
        found on the rest pose: the sign whose heads match the reflection, 0 where neither does."""
        body = self.body
        names = body.dof_names
        partner = np.arange(len(names))
        sign = np.zeros(len(names))
        rest = body.default_pose()
        for i, name in enumerate(names):
            if body.dofs[i].kind != "angle":
                continue
            other = name[:2].translate(str.maketrans("lr", "rl")) + name[2:] if name[:2] in ("l_", "r_") else name
            if other not in names:
                continue
            j = names.index(other)
            turned = rest.copy()
            turned[i] = self.TEST_ANGLE
            target = self._reflect(body.joint_positions(turned[None])[0])
            trials = np.repeat(rest[None], 2, axis=0)
            trials[:, body.root_rotation_dofs] = (0.0, 0.0, np.pi)  # the rest turned round about the vertical
            trials[:, j] = (self.TEST_ANGLE, -self.TEST_ANGLE)
            miss = np.abs(body.joint_positions(trials) - target[None]).max(axis=(1, 2))
            best = int(np.argmin(miss))
            if miss[best] < 0.2 * miss[1 - best]:
                partner[j], sign[j] = i, (1.0, -1.0)[best]
        return partner, sign

    def reflected(self, pose):
        """Absolute pose -> the absolute pose whose bone heads are this pose's reflected through its frontal plane
        (through the root), each bone taking its partner's place; None when the trunk gives no facing."""
        body = self.body
        pose = np.asarray(pose, float)
        targets = self._reflect(body.joint_positions(pose[None])[0])
        if targets is None:
            return None
        start = body.default_pose()
        angles = np.array([d.kind == "angle" for d in body.dofs])
        start[angles] = (self.dof_sign * pose[self.dof_partner])[angles]
        start = initial_root(body, targets, body.clamp(start))
        fitted, _ = fit_pose(body, targets, start, hold_weight=0.01)
        return fitted
