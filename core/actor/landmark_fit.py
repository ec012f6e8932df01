"""Fit the actor's proportions to the learned landmarks of a few tracked frames.

Each frame's landmarks are triangulated (left/right swaps resolved per view, core/evidence/keypoint_fit.py). Then
two steps alternate: every frame's pose is fitted to its 3D landmarks with the current body, and the
segment factors are fitted to all frames at once with the poses held (least squares, robust loss).
The rig's landmark points move with the scaled bones, landmark offsets included (they are in units of
the trunk, core/evidence/keypoints.py), so the factors answer "which body, posed, puts its landmark points where
the landmarks are". A weak pull towards the body's overall scale keeps segments the landmarks barely see
(the neck) in proportion. Symmetric by default: one factor per segment for both sides.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from ..evidence.keypoint_fit import align_root, triangulated_landmarks
from ..evidence.keypoints import KeypointTargets, landmark_weights, rig_keypoints
from .frames import MIN_FRAMES
from .proportions import SEGMENTS, Proportions, scaled_body, segment_lengths

MIN_POINTS = 10          # triangulated landmarks (of 15) for a frame to take part
PULL_TO_OVERALL = 0.02   # metres of residual per unit of log(factor / overall): weak, so the landmarks decide
# ...but the neck is seen through one landmark (the nose), which its three angles can reach at almost any
# length: it follows the body's overall scale unless the landmarks insist.
PULL_NECK = 0.3
ROBUST_SCALE = 0.03      # metres: soft-L1 scale of the landmark residuals (a swapped wrist costs ~linearly)


class ProportionsFitError(InputError):
    """Too little evidence to fit proportions (names what is missing and the fix)."""


@dataclass
class ProportionsFit:
    proportions: Proportions
    lengths: dict          # segment lengths of the fitted body, metres (core.actor.proportions.segment_lengths)
    subject_lengths: dict  # the same for the subject the fit started from
    frames: list           # capture frames used
    rms_before: float      # landmark residual (m) of the subject, poses fitted
    rms_after: float       # the same with the fitted body
    poses: np.ndarray      # (F,D) the fitted body's poses for `frames`
    # the silhouette refinement (core/actor/silhouette_fit.py), when it ran: the segments it refined, the
    # landmark fit's factors, the mask mismatch before and after
    silhouettes: dict | None = None
    measured: dict | None = None  # lengths the user measured on the actor, applied (core/actor/measured_lengths.py)


def targets_from_landmarks(uv, visibility, rig_points):
    """KeypointTargets for one frame's saved landmarks: uv (C,33,2) image pixels, visibility (C,33)."""
    uv = np.asarray(uv, float)[:, rig_points.landmarks]
    vis = np.asarray(visibility, float)[:, rig_points.landmarks]
    found = np.asarray(visibility, float).max(axis=1) > 0  # a view without evidence has visibility 0
    weight = np.where(found[:, None], landmark_weights(vis), 0.0)
    ok = np.isfinite(uv).all(axis=2)
    return KeypointTargets(np.where(ok[..., None], uv, 0.0), np.where(ok, weight, 0.0), np.ones(len(uv)))


def _factor_keys(symmetric):
    if symmetric:
        return list(SEGMENTS)
    sided = ("upper_arm", "forearm", "thigh", "shin", "foot")
    return [s for s in SEGMENTS if s not in sided] + [f"{side}_{s}" for s in sided for side in "lr"]


def _proportions(keys, log_factors):
    factors = dict(zip(keys, np.exp(log_factors)))
    overall = float(np.exp(np.mean(log_factors))) if len(keys) else 1.0  # head, hands, girth: the geometric mean
    return Proportions(factors, overall)


def _light_body(body, rig):
    """The body with only the skin the fit needs (the nose vertex and the soles, for the floor): scaling and
    posing it is what the fit repeats thousands of times."""
    from ..body.model import Body

    from ..evidence.keypoints import LANDMARK_POINTS, _front_vertex

    keep = set(np.argsort(body.vertices @ body.skeleton.armature_rotation.T[:, 2])[:100].tolist())
    for role, where in LANDMARK_POINTS.values():
        if where == "front":  # the same vertex rig_keypoints picks (it stays the most forward one when scaled)
            _, p = _front_vertex(body, role)
            keep.add(int(np.argmin(np.linalg.norm(body.vertices - p, axis=1))))
    keep = np.array(sorted(keep))
    return Body(body.skeleton, body.dofs, body.vertices[keep], np.zeros((1, 3), np.int64), body.weights[keep],
                body.root_bone, body.roles, body.preset)


class _JointProblem:
    """Factors and every frame's pose at once: residuals and a sparse finite-difference Jacobian whose
    pose columns are evaluated for all frames in one batched forward-kinematics call per DOF."""

    def __init__(self, light, keys, points, oks, poses0, hold=0.02, pull=None, landmarks="full"):
        self.light, self.keys, self.points, self.oks = light, keys, points, oks
        self.landmarks = landmarks
        self.poses0 = poses0
        self.F, self.D = poses0.shape
        self.n = len(keys)
        held = np.concatenate([light.translation_dofs, light.root_rotation_dofs])
        self.pulled = np.setdiff1d(np.arange(self.D), held)
        self.hold = hold
        pull = PULL_TO_OVERALL if pull is None else pull
        self.pull = np.array([PULL_NECK if k.endswith("neck") else pull for k in keys])
        self.frame_of_row = np.concatenate([np.repeat(np.nonzero(ok)[0] * 0 + f, 3) for f, ok in enumerate(oks)]
                                           + [np.repeat(np.arange(self.F), len(self.pulled))])

    def split(self, v):
        return v[:self.n], v[self.n:].reshape(self.F, self.D)

    def residuals(self, v, body=None):
        z, X = self.split(v)
        body = body or scaled_body(self.light, _proportions(self.keys, z))
        rig = rig_keypoints(body, self.landmarks)
        world = rig.world(body, X)
        lm = np.concatenate([(world[f] - self.points[f])[ok].ravel() for f, ok in enumerate(self.oks)])
        hold = self.hold * (X[:, self.pulled] - self.poses0[:, self.pulled]).ravel()
        return np.concatenate([lm, hold, self.pull * (z - z.mean()) if self.n else z])

    def jacobian(self, v, step=1e-4):
        from scipy.sparse import coo_matrix

        z, X = self.split(v)
        body = scaled_body(self.light, _proportions(self.keys, z))
        r0 = self.residuals(v, body)
        m = len(r0)
        rows, cols, vals = [], [], []
        for j in range(self.n):
            dv = v.copy()
            dv[j] += step
            col = (self.residuals(dv) - r0) / step
            nz = np.nonzero(col)[0]
            rows.append(nz), cols.append(np.full(len(nz), j)), vals.append(col[nz])
        n_pose_rows = m - self.n
        for d in range(self.D):
            dv = v.copy()
            dv[self.n + d::self.D] += step  # DOF d of every frame at once: frames do not interact
            col = (self.residuals(dv, body) - r0)[:n_pose_rows] / step
            nz = np.nonzero(col)[0]
            rows.append(nz), cols.append(self.n + self.frame_of_row[nz] * self.D + d), vals.append(col[nz])
        rows, cols, vals = (np.concatenate(a) for a in (rows, cols, vals))
        return coo_matrix((vals, (rows, cols)), shape=(m, len(v))).tocsr()


def _solve(problem, log_f, poses, max_nfev):
    light = problem.light
    lo = np.concatenate([np.full(problem.n, np.log(0.6)), np.tile(light.lower, problem.F)])
    hi = np.concatenate([np.full(problem.n, np.log(1.6)), np.tile(light.upper, problem.F)])
    v0 = np.concatenate([log_f, poses.ravel()])
    v0 = np.clip(v0, np.where(np.isfinite(lo), lo + 1e-9, lo), np.where(np.isfinite(hi), hi - 1e-9, hi))
    result = least_squares(problem.residuals, v0, jac=problem.jacobian, bounds=(lo, hi), loss="soft_l1",
                           f_scale=ROBUST_SCALE, tr_solver="lsmr", max_nfev=max_nfev, x_scale=1.0)
    return problem.split(result.x)


def _rms(body, poses, points, oks, landmarks):
    rig = rig_keypoints(body, landmarks)
    d = rig.world(body, poses) - points
    return float(np.sqrt(np.sum(np.square(d[oks])) / max(1, oks.sum())))


def fit_proportions(subject, cameras, landmarks, visibility, poses, frames=None, symmetric=True, max_nfev=60,
                    model="full"):
    """Fit segment factors for `subject` (a Body) to tracked frames.

    landmarks (F,C,33,2), visibility (F,C,33): the learned landmarks of the frames (keypoints.npz);
    poses (F,D): the subject's tracked poses of the same frames (starting points); model: the landmark model that
    placed the landmarks (core/evidence/keypoints.py, offsets_table). Returns a ProportionsFit.
    """
    rig0 = rig_keypoints(subject, model)
    points, oks = [], []
    for uv, vis in zip(landmarks, visibility):
        X, ok = triangulated_landmarks(cameras, targets_from_landmarks(uv, vis, rig0), rig0)
        points.append(np.where(ok[:, None], X, 0.0))
        oks.append(ok)
    points, oks = np.array(points), np.array(oks)
    use = oks.sum(axis=1) >= MIN_POINTS
    if use.sum() < MIN_FRAMES:
        raise ProportionsFitError(
            f"only {int(use.sum())} of {len(oks)} frames have {MIN_POINTS} or more landmarks seen by two views; "
            f"calibration needs {MIN_FRAMES}: use frames where the whole person is in view of at least two cameras")
    points, oks = points[use], oks[use]
    poses = np.array(poses, float)[use]
    frames = list(np.asarray(frames if frames is not None else range(len(use)))[use])
    keys = _factor_keys(symmetric)
    light = _light_body(subject, rig0)
    # the subject's own best fit first (poses only), for the before/after residual
    poses = np.array([align_root(light, rig0, x, X, ok) for x, X, ok in zip(poses, points, oks)])
    fixed = _JointProblem(light, [], points, oks, poses, landmarks=model)
    _, poses = _solve(fixed, np.zeros(0), poses, max_nfev=20)
    rms_before = _rms(light, poses, points, oks, model)
    problem = _JointProblem(light, keys, points, oks, poses, landmarks=model)
    log_f, poses = _solve(problem, np.zeros(len(keys)), poses, max_nfev)
    proportions = _proportions(keys, log_f)
    rms_after = _rms(scaled_body(light, proportions), poses, points, oks, model)
    return ProportionsFit(proportions, segment_lengths(scaled_body(subject, proportions)), segment_lengths(subject),
                          [int(f) for f in frames], rms_before, rms_after, poses)


def proportions_for_lengths(body, lengths, iterations=4):
    """The factors that give `body` these segment lengths (metres, as segment_lengths reports them): a saved
    calibration applied to another rig. Fixed-point: the widths share a bone with the spine, so repeat."""
    factors = {s: 1.0 for s in SEGMENTS if s in lengths}
    base = segment_lengths(body)
    for s in factors:
        factors[s] = lengths[s] / base[s]
    for _ in range(iterations):
        p = Proportions(factors, float(np.exp(np.mean(np.log(list(factors.values()))))))
        got = segment_lengths(scaled_body(body, p))
        factors = {s: f * lengths[s] / got[s] for s, f in factors.items()}
    return Proportions(factors, float(np.exp(np.mean(np.log(list(factors.values()))))))
