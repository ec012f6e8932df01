"""Body landmarks of the learned model on the tracker's rig: which rig point each landmark stands for,
and the keypoint energy term that compares them in every view.

LANDMARK_POINTS is the one place that maps BlazePose landmarks onto the rig, by joint role (so every
rig preset works):
  ("role", "head")   the head of the role's first bone (the joint the segment starts at)
  ("role", "socket") the same joint, carried by that bone's parent (the clavicle, the pelvis): for landmarks on
                     the trunk side of a ball joint, which stay put when the limb turns
  ("role", "end")    the head of the first child of the role's last bone (the joint it ends at)
  ("role", "front")  the most forward mesh vertex of the role's body part above the role's end
                     (the nose on the head), carried by the bone that weighs most on that vertex
BlazePose's landmarks do not sit on the rig's joints: LANDMARK_OFFSETS moves each rig point to where
the model puts that landmark, measured on the walk and playground scenes (see its comment).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .learned import SWAP_ORDER

LANDMARK_POINTS = {
    0: ("neck", "front"),                            # nose
    11: ("l_shoulder", "socket"), 12: ("r_shoulder", "socket"),
    13: ("l_elbow", "head"), 14: ("r_elbow", "head"),
    15: ("l_elbow", "end"), 16: ("r_elbow", "end"),  # wrists
    23: ("l_hip", "socket"), 24: ("r_hip", "socket"),
    25: ("l_knee", "head"), 26: ("r_knee", "head"),
    27: ("l_ankle", "head"), 28: ("r_ankle", "head"),
    31: ("l_ankle", "end"), 32: ("r_ankle", "end"),  # foot index ~ the toes' base
}
# Where BlazePose puts a landmark relative to the rig point above, in the carrying bone's frame: (outwards
# for the landmark's side, forwards, up) in units of the rig's trunk (root head to neck head), so the same
# numbers serve any rig size. Measured on walk and playground by tools/landmark_offsets.py --raw: the hips sit
# forward of the hip joints, the wrists and shoulders inside the joints. The shoulders and hips are carried by the
# trunk ("socket"), whose side of the joint they lie on, so their offsets do not turn with the limb
# (docs/defaults.md, "LANDMARK_OFFSETS").
LANDMARK_OFFSETS = {
    0: (0.0, -0.036, -0.060),
    11: (-0.028, -0.026, 0.033), 13: (0.019, 0.057, 0.026), 15: (-0.043, 0.030, 0.024),
    23: (-0.013, 0.083, -0.009), 25: (0.031, -0.037, -0.026), 27: (0.049, -0.001, 0.038),
    31: (0.051, -0.001, -0.058),
}
# The heavy model places the same landmarks otherwise: the elbows and knees about 0.03-0.04 trunk further in, the
# ankles 0.04 lower, measured the same way (docs/defaults.md, "landmarks").
HEAVY_LANDMARK_OFFSETS = {
    0: (0.0, -0.032, -0.058),
    11: (-0.039, -0.022, 0.040), 13: (-0.022, 0.054, 0.017), 15: (-0.053, 0.028, 0.011),
    23: (-0.024, 0.072, -0.002), 25: (0.003, -0.031, -0.036), 27: (0.046, 0.000, -0.005),
    31: (0.050, 0.014, -0.074),
}


OFFSETS_OF_MODEL = {"full": LANDMARK_OFFSETS, "heavy": HEAVY_LANDMARK_OFFSETS}


def offsets_table(model="full"):
    """The offsets table of the landmark model `model` (core/evidence/learned.py, LANDMARK_MODEL_FILES): a model
    without a table of its own is refused, not given another model's."""
    if model not in OFFSETS_OF_MODEL:
        raise KeypointMapError(f"landmark model {model!r} has no offsets table; the tables are for "
                               f"{', '.join(OFFSETS_OF_MODEL)}")
    return OFFSETS_OF_MODEL[model]
# Robust loss rho(r) = r^2 / (r^2 + sigma^2) on the distance r in units of the person's size in the view
# (the crop side / margin): a landmark off by more than a few sigma costs ~1 whatever its distance, so
# one wrong landmark cannot drag a limb.
KEYPOINT_SIGMA = 0.05
# A landmark's weight: VISIBILITY_FLOOR + (1 - VISIBILITY_FLOOR) x its visibility. BlazePose's visibility
# says whether a landmark is occluded, not how well it is placed: an occluded wrist is still placed within a few
# centimetres most of the time, so it counts, with less weight (docs/defaults.md, "VISIBILITY_FLOOR").
VISIBILITY_FLOOR = 0.25
# A heatmap's second guess (core/evidence/learned.py, heatmap_alternatives) costs what the regressed point
# would plus this much per logit it lies below the landmark's top peak: a close runner-up is nearly as good
# an explanation; one ALTERNATIVE_MAX_GAP (3) logits down costs 0.75 more, close to an outlier's 1.
ALTERNATIVE_COST_PER_LOGIT = 0.25


def landmark_weights(visibility):
    """A landmark's weight from its visibility: VISIBILITY_FLOOR + (1 - VISIBILITY_FLOOR) x visibility."""
    return VISIBILITY_FLOOR + (1 - VISIBILITY_FLOOR) * np.asarray(visibility, dtype=np.float64)


class KeypointMapError(InputError):
    """The rig lacks a bone a landmark needs."""


@dataclass
class RigKeypoints:
    """Rest-space points on the rig that the landmarks stand for, each carried by one bone."""
    landmarks: np.ndarray   # (K,) BlazePose landmark index per point
    bones: np.ndarray       # (K,) bone carrying the point
    rest_points: np.ndarray  # (K,4) homogeneous rest armature-space positions
    swap: np.ndarray        # (K,) index of the mirrored point (itself for the nose)

    def world(self, body, poses, root_anchor=None):
        """(P,D) -> (P,K,3) world positions of the points."""
        M = body.skinning_matrices(np.atleast_2d(poses), root_anchor)[:, self.bones]  # (P,K,4,4)
        return np.einsum("pkij,kj->pki", M, self.rest_points)[..., :3]


def _front_vertex(body, role):
    sk = body.skeleton
    part = body.part_names.index(role)
    vertex_part = body.bone_part[np.argmax(body.weights, axis=1)]
    end = sk.rest[end_bone(body, role), :3, 3]
    frame_forward, frame_up = _rest_axes(body)
    candidates = np.nonzero((vertex_part == part) & ((body.vertices - end) @ frame_up > 0))[0]
    if len(candidates) == 0:
        raise KeypointMapError(f"no mesh vertex of the {role!r} part above its end joint: cannot place the nose")
    v = candidates[np.argmax(body.vertices[candidates] @ frame_forward)]
    return int(np.argmax(body.weights[v])), body.vertices[v]


def _rest_axes(body):
    from ..body.model import body_frame

    frame = body_frame(body.skeleton, body.roles)
    return frame.forward, frame.up


def end_bone(body, role):
    sk = body.skeleton
    last = sk.index[body.roles[role][-1]]
    children = sk.children_of(last)
    if not children:
        raise KeypointMapError(f"the bone {body.roles[role][-1]!r} ({role}) has no child bone, so the joint it "
                               "ends at is unknown; add a child bone (hand or toe)")
    # The child that continues the bone (the one whose head lies farthest along it: the hand, not a thumb).
    heads = sk.rest[children, :3, 3] - sk.rest[last, :3, 3]
    axis = sk.rest[last, :3, 1]
    return children[int(np.argmax(heads @ axis))]


def rig_keypoints(body, model="full"):
    """The rig points of LANDMARK_POINTS for `body` (any preset), where the landmark model `model` puts them."""
    sk = body.skeleton
    landmarks, bones, points = [], [], []
    for lm, (role, where) in LANDMARK_POINTS.items():
        if role not in body.roles:
            raise KeypointMapError(f"the rig has no {role!r} joint for landmark {lm}")
        if where in ("head", "socket"):
            b = sk.index[body.roles[role][0]]
            p = sk.rest[b, :3, 3]
            if where == "socket" and sk.parents[b] >= 0:
                b = int(sk.parents[b])
        elif where == "end":
            b = sk.index[body.roles[role][-1]]
            p = sk.rest[end_bone(body, role), :3, 3]
        else:
            b, p = _front_vertex(body, role)
        landmarks.append(lm)
        bones.append(b)
        points.append(np.append(p, 1.0))
    landmarks = np.array(landmarks)
    where = {lm: i for i, lm in enumerate(landmarks)}
    swap = np.array([where.get(int(SWAP_ORDER[lm]), i) for i, lm in enumerate(landmarks)])
    points = np.array(points)
    points[:, :3] += landmark_offsets(body, landmarks, model)
    return RigKeypoints(landmarks, np.array(bones), points, swap)


def landmark_offsets(body, landmarks, model="full"):
    """(K,3) rest-space shift of each landmark's rig point: the model's table (offsets_table), mirrored for the
    right side."""
    from ..body.model import body_frame

    sk = body.skeleton
    frame = body_frame(sk, body.roles)
    trunk = np.linalg.norm(sk.rest[sk.index[body.roles["neck"][0]], :3, 3]
                           - sk.rest[sk.index[body.roles["root"][0]], :3, 3])
    table = offsets_table(model)
    out = np.zeros((len(landmarks), 3))
    for i, lm in enumerate(landmarks):
        side = 1.0 if lm in table else -1.0  # the table holds the nose and the left side
        outwards, forwards, up = table.get(int(lm), table.get(int(SWAP_ORDER[lm]), (0, 0, 0)))
        out[i] = trunk * (side * outwards * frame.left + forwards * frame.forward + up * frame.up)
    return out


@dataclass
class KeypointTargets:
    """One frame's landmarks for the rig points: (C,K,2) capture pixels, (C,K) weights, (C,) person size;
    optionally each landmark's second guesses from the heatmaps, (C,K,A,2) pixels and (C,K,A) extra cost
    (inf where there is none)."""
    uv: np.ndarray
    weight: np.ndarray
    person_px: np.ndarray
    alt_uv: np.ndarray | None = None
    alt_cost: np.ndarray | None = None

    def scaled(self, factor):
        """The same landmarks for cameras scaled by `factor` (Camera.scaled)."""
        alt = None if self.alt_uv is None else (self.alt_uv + 0.5) * factor - 0.5
        return KeypointTargets((self.uv + 0.5) * factor - 0.5, self.weight, self.person_px * factor, alt,
                               self.alt_cost)

    def candidates(self):
        """(C,K,1+A,2) positions and (C,K,1+A) extra costs: the regressed landmark first, then its second
        guesses."""
        uv, cost = self.uv[:, :, None], np.zeros(self.uv.shape[:2] + (1,))
        if self.alt_uv is None:
            return uv, cost
        return np.concatenate([uv, self.alt_uv], axis=2), np.concatenate([cost, self.alt_cost], axis=2)

    @classmethod
    def from_evidence(cls, evidence, rig_points, margin, alternatives=True):
        uv = np.stack([ev.keypoints[rig_points.landmarks] for ev in evidence])
        weight = np.stack([landmark_weights(ev.visibility[rig_points.landmarks])
                           if ev.found else np.zeros(len(rig_points.landmarks)) for ev in evidence])
        size = np.array([ev.box.size / margin if ev.box is not None else 1.0 for ev in evidence])
        uv = np.where(np.isfinite(uv), uv, 0.0)
        alt_uv = alt_cost = None
        if alternatives and any(ev.alternatives is not None for ev in evidence):
            n_alt = max(ev.alternatives.shape[1] for ev in evidence if ev.alternatives is not None)
            alt = np.full((len(evidence), len(rig_points.landmarks), n_alt, 3), np.nan)
            for c, ev in enumerate(evidence):
                if ev.found and ev.alternatives is not None:
                    alt[c, :, :ev.alternatives.shape[1]] = ev.alternatives[rig_points.landmarks]
            missing = ~np.all(np.isfinite(alt), axis=-1)
            alt_uv = np.where(missing[..., None], 0.0, alt[..., :2])
            alt_cost = np.where(missing, np.inf, ALTERNATIVE_COST_PER_LOGIT * alt[..., 2])
        return cls(uv, weight, size, alt_uv, alt_cost)


def _candidate_costs(projected, targets, order, sigma):
    """(P,C,K) rho of each projected rig point against landmark order[k] (weights included): the cheapest
    of that landmark's candidates, and which candidate it was."""
    uv, extra = targets.candidates()
    uv, extra, w = uv[:, order], extra[:, order], targets.weight[:, order]
    d2 = np.sum((projected[:, :, :, None] - uv[None]) ** 2, axis=-1)          # (P,C,K,1+A)
    r2 = (1.0 / (sigma * targets.person_px[None, :, None, None])) ** 2
    rho = np.minimum(d2 * r2 / (d2 * r2 + 1) + extra[None], 1.0)
    best = np.argmin(rho, axis=-1)
    return w[None] * np.take_along_axis(rho, best[..., None], axis=-1)[..., 0], best


def assigned_costs(projected, targets, swap, sigma=KEYPOINT_SIGMA):
    """Per point (P,C,K): its weighted rho, whether its view's left/right pair is taken the other way round,
    and which candidate of the landmark it matched (0: the regressed point). Each pair is assigned the way
    that costs less (single-view detectors swap sides), each landmark's cheapest candidate counted."""
    K = projected.shape[2]
    rho_same, best_same = _candidate_costs(projected, targets, np.arange(K), sigma)
    rho_swap, best_swap = _candidate_costs(projected, targets, swap, sigma)
    pair_same = rho_same + rho_same[:, :, swap]  # a pair's cost under each assignment
    pair_swap = rho_swap + rho_swap[:, :, swap]
    flip = pair_swap < pair_same
    return np.where(flip, rho_swap, rho_same), flip, np.where(flip, best_swap, best_same)


def keypoint_energy(projected, targets, swap, sigma=KEYPOINT_SIGMA):
    """keypoint_energy_reference in numba (core/evidence/keypoints_fast.py) when numba is there."""
    global _FAST_ENERGY
    if _FAST_ENERGY is None:
        try:
            from .keypoints_fast import keypoint_energy as fast
        except ImportError:
            fast = keypoint_energy_reference
        _FAST_ENERGY = fast
    return _FAST_ENERGY(projected, targets, swap, sigma)


_FAST_ENERGY = None


def keypoint_energy_reference(projected, targets, swap, sigma=KEYPOINT_SIGMA):
    """Projected rig points (P,C,K,2) vs landmarks -> (P,) energy, about [0, 1].

    Per view: the weighted mean of rho over the points; each left/right pair counts with whichever
    assignment fits the pose better (single-view detectors swap sides; the other views and the other cues
    decide), and each landmark with whichever of its candidates (the regressed point, the heatmap's second
    guesses at their extra cost) fits better. Views without landmarks are left out; the mean is over the
    views that have some.
    """
    per_point, _, _ = assigned_costs(projected, targets, swap, sigma)
    w = targets.weight
    total_w = w.sum(axis=1)  # swapping permutes the weights within pairs: same total
    seen = total_w > 1e-6
    if not seen.any():
        return np.zeros(projected.shape[0])
    per_view = per_point.sum(axis=2)[:, seen] / total_w[seen][None]
    return per_view.mean(axis=1)


# Landmarks that tell where each limb is (the limb names of core/tracking/limb_search.LIMB_ROLES).
LIMB_LANDMARKS = {"left arm": (13, 15), "right arm": (14, 16), "left leg": (25, 27), "right leg": (26, 28)}


def chosen_targets(projected, targets, swap, sigma=KEYPOINT_SIGMA):
    """What each rig point of one pose is compared with, as in the energy: projected (C,K,2) -> the chosen
    landmark position (C,K,2) (its pair's assignment, its cheapest candidate) and that landmark's weight."""
    _, flip, best = assigned_costs(projected[None], targets, swap, sigma)
    flip, best = flip[0], best[0]
    K = projected.shape[1]
    landmark = np.where(flip, swap[None, :], np.arange(K)[None, :])               # (C,K)
    uv, _ = targets.candidates()
    chosen = uv[np.arange(len(uv))[:, None], landmark, best]                       # (C,K,2)
    return chosen, np.take_along_axis(targets.weight, landmark, axis=1)


def limb_disagreement(projected, targets, rig_points, min_weight=0.2):
    """How far each limb of one pose lies from its landmarks: projected (C,K,2) -> {limb: median distance
    in units of the person's size over the views and points that see it (NaN where none does)}.

    Each point is compared with what the energy compares it with (chosen_targets)."""
    chosen, w = chosen_targets(projected, targets, rig_points.swap)
    d = np.linalg.norm(projected - chosen, axis=-1) / targets.person_px[:, None]    # (C,K)
    index = {int(lm): i for i, lm in enumerate(rig_points.landmarks)}
    out = {}
    for limb, landmarks in LIMB_LANDMARKS.items():
        idx = [index[lm] for lm in landmarks if lm in index]
        values = d[:, idx][w[:, idx] >= min_weight]
        out[limb] = float(np.median(values)) if values.size else float("nan")
    return out
