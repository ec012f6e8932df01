"""Actor proportions: how much longer or shorter each segment of the tracker's skeleton is for the person
in the footage, and the body that makes (bones lengthened, the skin moved with them).

A segment is a group of bones named by joint role, so every rig preset works:
  spine      the root and spine bones (root head to neck head)
  neck       the neck bones (neck head to the head bone's head)
  upper_arm / forearm / thigh / shin / foot   the shoulder / elbow / hip / knee / ankle role's bones
  shoulder_width / hip_width   the step from the trunk to the arm's / leg's first joint (a clavicle or hip
             bone, or the root's offset to the thigh in rigs without one)
Every other bone (head, hands, toes, fingers) follows `overall`, which also sets the girth of the skin.
A factor is absolute (1.0 = the subject's own length), per segment, the same on both sides unless a
sided key ("l_forearm") is given. Bone rest orientations never change, so a pose vector means the same
joint rotations on the subject and on the scaled body: that is what lets the actor's solved rotations key
the user's character unchanged.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

SEGMENTS = ("spine", "neck", "shoulder_width", "upper_arm", "forearm", "hip_width", "thigh", "shin", "foot")
_ROLE_SEGMENT = {"root": "spine", "spine": "spine", "neck": "neck", "shoulder": "upper_arm", "elbow": "forearm",
                 "hip": "thigh", "knee": "shin", "ankle": "foot"}
_WIDTH_SEGMENT = {"shoulder": "shoulder_width", "hip": "hip_width"}


class ProportionsError(InputError):
    """Proportions that cannot apply: a bad factor, a file that is not a calibration."""


@dataclass
class Proportions:
    """Segment factors (absolute: 1.0 = the subject's length). Missing segments follow `overall`."""
    factors: dict = field(default_factory=dict)
    overall: float = 1.0

    def __post_init__(self):
        self.factors = {str(k): float(v) for k, v in self.factors.items()}
        self.overall = float(self.overall)
        for key, value in [*self.factors.items(), ("overall", self.overall)]:
            if not (np.isfinite(value) and 0.5 <= value <= 2.0):
                raise ProportionsError(f"segment factor {key} = {value} is outside 0.5-2.0: a person is not "
                                       "half or twice the subject's size in one segment; recalibrate")
            if key != "overall" and key not in SEGMENTS and not (key[:2] in ("l_", "r_") and key[2:] in SEGMENTS):
                raise ProportionsError(f"unknown segment {key!r}; segments are {', '.join(SEGMENTS)}")

    def factor(self, segment, side=""):
        if segment == "overall":
            return self.overall
        return self.factors.get(f"{side}_{segment}", self.factors.get(segment, self.overall))

    @classmethod
    def uniform(cls, scale):
        return cls({}, scale)

    @property
    def is_identity(self):
        """Every segment the subject's own length: the calibration kept the rig."""
        return self.overall == 1.0 and all(v == 1.0 for v in self.factors.values())


def _side_and_stem(role):
    if role[:2] in ("l_", "r_"):
        return role[0], role[2:]
    return "", role


def bone_segments(bone_names, parents, roles):
    """Per bone (segment, side) whose factor scales the bone itself (its tail and its skin), and per bone
    the (segment, side) that scales the offset from its parent's head to its own head."""
    index = {n: i for i, n in enumerate(bone_names)}
    own = {}
    for role, bones in roles.items():
        side, stem = _side_and_stem(role)
        for name in bones:
            own[index[name]] = (_ROLE_SEGMENT[stem], side)
    first_of_width = {}
    for role, bones in roles.items():
        side, stem = _side_and_stem(role)
        if stem in _WIDTH_SEGMENT:
            first = index[bones[0]]
            first_of_width[first] = (_WIDTH_SEGMENT[stem], side)
            b = parents[first]
            while b >= 0 and b not in own:  # clavicle / hip bone between the trunk and the limb
                own[b] = (_WIDTH_SEGMENT[stem], side)
                b = parents[b]
    own_list = [own.get(b, ("overall", "")) for b in range(len(bone_names))]
    link = [first_of_width.get(b, own_list[parents[b]] if parents[b] >= 0 else ("overall", ""))
            for b in range(len(bone_names))]
    return own_list, link


def scale_rest(heads, axes, parents, order, own_factor, link_factor, vertices, weights, girth, up):
    """Lengthen each bone by its factor and move the skin with it.

    heads, axes (B,3): rest heads and unit bone directions; own_factor, link_factor (B,); vertices (V,3),
    weights (V,B) normalised (rows of zeros stay put); girth: the skin's scale across the bones. Each
    bone maps a rest point p to new_head + girth (p - head) + (own - girth) ((p - head).axis) axis; a
    vertex blends these with its skin weights, so the skin of a longer forearm stretches along it and the
    hand skin rides on the moved wrist. The result is shifted along `up` so the lowest skin point stays
    where it was (the scaled body stands on the same floor). Returns new heads and vertices."""
    heads = np.asarray(heads, float)
    new_heads = heads.copy()
    for b in order:
        p = parents[b]
        if p >= 0:
            new_heads[b] = new_heads[p] + link_factor[b] * (heads[b] - heads[p])
    vertices = np.asarray(vertices, float)
    new_vertices = vertices.copy()
    total = weights.sum(axis=1)
    weighted = total > 0
    for b in range(len(heads)):
        w = weights[:, b]
        on = np.nonzero(w > 0)[0]
        if len(on) == 0:
            continue
        rel = vertices[on] - heads[b]
        along = rel @ axes[b]
        moved = new_heads[b] + girth * rel + ((own_factor[b] - girth) * along)[:, None] * axes[b]
        new_vertices[on] += w[on, None] * (moved - vertices[on])
    lowest_before = (vertices[weighted] @ up).min() if weighted.any() else 0.0
    lowest_after = (new_vertices[weighted] @ up).min() if weighted.any() else 0.0
    shift = (lowest_before - lowest_after) * np.asarray(up, float)
    new_vertices[weighted] += shift
    return new_heads + shift, new_vertices


def bone_factors(bone_names, parents, roles, proportions):
    own, link = bone_segments(bone_names, parents, roles)
    return (np.array([proportions.factor(s, side) for s, side in own]),
            np.array([proportions.factor(s, side) for s, side in link]))


def scaled_body(body, proportions):
    """A copy of `body` with the proportions applied: rest heads moved, rest orientations kept, the mesh
    moved with its bones; same DOF layout, so the same pose vectors apply."""
    from ..body.model import Body, Skeleton

    sk = body.skeleton
    own, link = bone_factors(sk.bone_names, sk.parents, body.roles, proportions)
    up = _world_up(sk)
    heads, vertices = scale_rest(sk.rest[:, :3, 3], sk.rest[:, :3, 1], sk.parents, sk.order, own, link,
                                 body.vertices, body.weights, proportions.overall, up)
    rest = sk.rest.copy()
    rest[:, :3, 3] = heads
    skeleton = Skeleton(list(sk.bone_names), sk.parents.copy(), rest, sk.armature_matrix.copy())
    return Body(skeleton, copy.deepcopy(body.dofs), vertices, body.faces, body.weights, body.root_bone,
                body.roles, body.preset)


def _world_up(skeleton):
    """World +Z (the capture's floor normal, Blender's up) in the armature's space."""
    return skeleton.armature_rotation.T @ np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------- measuring a body
def _head(body, role, k=0):
    sk = body.skeleton
    return sk.rest[sk.index[body.roles[role][k]], :3, 3]


def _end(body, role):
    """The head of the child that continues the role's last bone (hand, toe, head bone); the last bone's own
    head when it has no child."""
    from ..evidence.keypoints import KeypointMapError, end_bone

    sk = body.skeleton
    try:
        return sk.rest[end_bone(body, role), :3, 3]
    except KeypointMapError:
        return sk.rest[sk.index[body.roles[role][-1]], :3, 3] + 0.0


def segment_lengths(body):
    """Rest lengths in metres: every segment per side ('l_forearm'), both sides' mean ('forearm'), the
    widths, and the standing height of the skin."""
    dist = np.linalg.norm
    out = {"spine": dist(_head(body, "neck") - _head(body, "root")),
           "neck": dist(_end(body, "neck") - _head(body, "neck")),
           "shoulder_width": dist(_head(body, "l_shoulder") - _head(body, "r_shoulder")),
           "hip_width": dist(_head(body, "l_hip") - _head(body, "r_hip"))}
    for seg, start, stop in (("upper_arm", "shoulder", "elbow"), ("thigh", "hip", "knee"), ("shin", "knee", "ankle")):
        for side in "lr":
            out[f"{side}_{seg}"] = dist(_head(body, f"{side}_{stop}") - _head(body, f"{side}_{start}"))
    for seg, role in (("forearm", "elbow"), ("foot", "ankle")):
        for side in "lr":
            out[f"{side}_{seg}"] = dist(_end(body, f"{side}_{role}") - _head(body, f"{side}_{role}"))
    for seg in ("upper_arm", "forearm", "thigh", "shin", "foot"):
        out[seg] = (out[f"l_{seg}"] + out[f"r_{seg}"]) / 2
    up = _world_up(body.skeleton)
    v = body.vertices[~body.unweighted] if (~body.unweighted).any() else body.vertices
    heights = v @ up
    out["height"] = float(heights.max() - heights.min())
    return {k: float(v) for k, v in out.items()}


# ---------------------------------------------------------------------- the actor's motion on the character
def standing_heights(body):
    """World Z of the rest skin's lowest point (the floor it stands on) and the root head's height above it."""
    sk = body.skeleton
    v = body.vertices[~body.unweighted] if (~body.unweighted).any() else body.vertices
    z = (v @ sk.armature_matrix[:3, :3].T + sk.armature_matrix[:3, 3])[:, 2]
    floor = float(z.min())
    return floor, float(sk.rest_heads_world()[body.root_bone, 2] - floor)


def character_poses(actor, character, poses, anchor_xy=None):
    """The actor's solved poses for the character: joint rotations as solved, the root's path scaled by the
    ratio of hip heights (the leg length) about the floor and about the first frame's root, so the character
    walks the actor's steps with its own legs and keeps its bones. poses (F,D) of `actor`; same DOF layout."""
    poses = np.array(poses, float, copy=True)
    t = poses[:, actor.translation_dofs]
    floor_a, hip_a = standing_heights(actor)
    floor_c, hip_c = standing_heights(character)
    ratio = hip_c / hip_a
    anchor_xy = t[0, :2] if anchor_xy is None else np.asarray(anchor_xy, float)
    out = np.empty_like(t)
    out[:, :2] = anchor_xy + ratio * (t[:, :2] - anchor_xy)
    out[:, 2] = floor_c + ratio * (t[:, 2] - floor_a)
    poses[:, character.translation_dofs] = out
    return poses
