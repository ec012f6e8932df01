"""The first frame from keypoints: triangulate the confident landmarks, fit the rig's root and limbs to them.

Single-view landmarks swap left and right now and then; each view's pairs are kept or swapped by
whichever assignment agrees with the other views (reprojection of the joint triangulation), before
the final triangulation. The fit then moves the rig's landmark points onto the 3D landmarks
(least squares over every DOF, within the joint limits, with a weak pull to the starting posture for
the angles the landmarks do not see). The global search then starts from this pose.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from .keypoints import LIMB_LANDMARKS
from ..body.rotations import best_rotation, matrix_to_rotvec, rotvec_to_matrix

MIN_WEIGHT = 0.2        # a landmark takes part in triangulation above this weight (every found view: see
                        # keypoints.VISIBILITY_FLOOR)
TORSO_LANDMARKS = (11, 12, 23, 24)
# A limb's landmark fit from rest (limb_landmark_fit) replaces the fit from the estimate when its rms residual is
# this much lower (metres) [DESIGN]: well under the gap between a stuck fit and one from rest; ties (the same fit
# reached both ways) keep the estimate's, so a run changes only where the fit was stuck (docs/defaults.md,
# "REST_START_GAIN").
REST_START_GAIN = 0.01


def triangulate(cameras, uv, weight, min_weight=MIN_WEIGHT):
    """DLT per point over the views where its weight passes: uv (C,K,2), weight (C,K) -> (K,3), ok (K,)."""
    return dlt_batched(*_projections_and_ideal(cameras, uv), weight, min_weight)


def _projections_and_ideal(cameras, uv):
    """(C,3,4) projection matrices and the (C,K,2) pixels an ideal (distortion-free) camera sees."""
    return (np.stack([cam.projection_matrix for cam in cameras]),
            np.stack([cam.undistort_points(uv[c]) for c, cam in enumerate(cameras)]))


def dlt_batched(P, ideal, weight, min_weight):
    """All points' DLT systems in one batched SVD: P (C,3,4), ideal (undistorted) pixels (C,K,2), weight
    (C,K). A view under min_weight contributes zero rows, which leave the solution (the null space of
    A^T A) as it is without them. A landmark without pixels (NaN: not found in that view) counts as weightless."""
    found = np.isfinite(ideal).all(axis=-1)
    w = np.where((weight >= min_weight) & found, weight, 0.0)  # (C,K)
    u, v = np.where(found, ideal[..., 0], 0.0), np.where(found, ideal[..., 1], 0.0)  # 0 x NaN would poison A
    row_u = w[..., None] * (u[..., None] * P[:, None, 2] - P[:, None, 0])  # (C,K,4)
    row_v = w[..., None] * (v[..., None] * P[:, None, 2] - P[:, None, 1])
    A = np.concatenate([row_u, row_v], axis=0).transpose(1, 0, 2)  # (K,2C,4)
    K = A.shape[0]
    X = np.full((K, 3), np.nan)
    ok = (w > 0).sum(axis=0) >= 2
    if not ok.any():
        return X, ok
    h = np.linalg.svd(A[ok])[2][:, -1]  # (n,4)
    finite = np.abs(h[:, 3]) > 1e-12
    idx = np.nonzero(ok)[0]
    X[idx[finite]] = h[finite, :3] / h[finite, 3:]
    ok[idx[~finite]] = False
    return X, ok


def resolve_swaps(cameras, uv, weight, swap, max_views=10):
    """Per left/right pair, the views whose sides are swapped: of every choice of a minority of views to
    swap, the one whose triangulation reprojects best. Returns uv, weight with those views' pairs swapped."""
    return resolve_swaps_with_projections(cameras, uv, weight, swap, max_views)[:2]


def resolve_swaps_with_projections(cameras, uv, weight, swap, max_views=10):
    """resolve_swaps, also returning the projection matrices and the ideal pixels (swapped alike) it used."""
    uv, weight = uv.copy(), weight.copy()
    C = weight.shape[0]
    P, ideal = _projections_and_ideal(cameras, uv)  # once: swaps permute the points, each undistorted alone
    for a, b in [(a, int(b)) for a, b in enumerate(swap) if a < b]:
        views = [c for c in range(C) if min(weight[c, a], weight[c, b]) >= MIN_WEIGHT]
        if len(views) < 3 or len(views) > max_views:  # two views cannot outvote each other
            continue
        flips = [[views[i] for i in range(len(views)) if mask >> i & 1] for mask in range(1 << len(views))]
        flips = [flip for flip in flips if 2 * len(flip) < len(views)]
        # Every trial's two points side by side: trial t's (a, b) are points 2t, 2t+1.
        order = np.tile([a, b], (C, len(flips)))  # (C, 2T): the landmark each view sees as each point
        for t, flip in enumerate(flips):
            order[flip, 2 * t:2 * t + 2] = [b, a]
        rows = np.arange(C)[:, None]
        X, ok = dlt_batched(P, ideal[rows, order], weight[rows, order], MIN_WEIGHT)
        good = ok.reshape(-1, 2).all(axis=1)
        if not good.any():
            continue
        err = np.zeros(len(flips))
        for c in views:
            seen = np.where(ok[:, None], X, 0.0)
            err += np.linalg.norm(cameras[c].project(seen) - uv[c, order[c]], axis=1).reshape(-1, 2).sum(axis=1)
        err[~good] = np.inf
        for c in flips[int(np.argmin(err))]:
            uv[c, [a, b]] = uv[c, [b, a]]
            weight[c, [a, b]] = weight[c, [b, a]]
            ideal[c, [a, b]] = ideal[c, [b, a]]
    return uv, weight, P, ideal


def align_root(body, rig_points, x, targets, ok):
    """Rotate and move the root of `x` so the rig's torso landmarks meet the triangulated ones (Kabsch)."""
    torso = np.array([i for i, lm in enumerate(rig_points.landmarks) if lm in TORSO_LANDMARKS and ok[i]])
    if len(torso) < 3:
        return x
    src = rig_points.world(body, x[None])[0][torso]
    dst = targets[torso]
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    R = best_rotation(src - cs, dst - cd)
    out = np.array(x, dtype=np.float64)
    rd, td = body.root_rotation_dofs, body.translation_dofs
    out[rd] = matrix_to_rotvec(R @ rotvec_to_matrix(out[rd]))
    root = out[td]
    out[td] = R @ (root - cs) + cd
    return out


def fit_to_points(body, rig_points, x0, targets, ok, hold=0.02, dofs=None, max_nfev=60):
    """Least squares of the rig's landmark points onto `targets` (K,3) where ok, within the limits, over
    every DOF or only `dofs` (the others held at x0)."""
    idx = np.nonzero(ok)[0]
    x0 = np.asarray(x0, dtype=np.float64)
    free = np.arange(body.n_dof) if dofs is None else np.asarray(dofs)
    held_root = np.concatenate([body.translation_dofs, body.root_rotation_dofs])
    pulled = np.setdiff1d(free, held_root)  # joint angles the landmarks may not see stay near x0

    def pose(z):
        x = x0.copy()
        x[free] = z
        return x

    def residuals(z):
        x = pose(z)
        pts = rig_points.world(body, x[None])[0][idx]
        return np.concatenate([(pts - targets[idx]).ravel(), hold * (x[pulled] - x0[pulled])])

    lo, hi = body.lower[free], body.upper[free]
    z0 = np.clip(x0[free], lo + 1e-9, hi - 1e-9)
    result = least_squares(residuals, z0, bounds=(lo, hi), loss="soft_l1", f_scale=0.05, max_nfev=max_nfev,
                           x_scale="jac")
    rms = float(np.sqrt(np.mean(np.square(result.fun[:3 * len(idx)])))) if len(idx) else np.inf
    return pose(result.x), rms


def limb_landmark_fit(body, rig_points, pose, X, ok, dofs):
    """`pose` (absolute) with the DOFs `dofs` fitted to the triangulated landmarks X (K,3) where ok, from two
    starts: the pose itself and those DOFs at rest; the rest's where the landmarks fit it clearly better. From the
    pose alone the least squares stays near it when the limb has moved far (an arm tracked raised while the
    person's hung at the side: docs/defaults.md, "REST_START_GAIN")."""
    near, near_rms = fit_to_points(body, rig_points, pose, X, ok, dofs=dofs, max_nfev=30)
    if near_rms <= REST_START_GAIN:  # no fit can be that much better
        return near
    at_rest = np.array(pose, float)
    at_rest[dofs] = body.default_pose()[dofs]
    rested, rested_rms = fit_to_points(body, rig_points, at_rest, X, ok, dofs=dofs, max_nfev=30)
    # both starts usually end in the same fit; only a clearly better one replaces the pose's own
    return rested if rested_rms < near_rms - REST_START_GAIN else near


def triangulated_landmarks(cameras, targets, rig_points):
    """The frame's landmarks in 3D: (K,3) points and (K,) ok, left/right swaps resolved per view."""
    _, weight, P, ideal = resolve_swaps_with_projections(cameras, targets.uv, targets.weight, rig_points.swap)
    return dlt_batched(P, ideal, weight, MIN_WEIGHT)


def limb_distances_3d(rig_points, world_points, X, ok):
    """{limb: the largest distance (metres) of its landmark points (elbow and wrist, knee and ankle) of one
    pose, world_points (K,3), from the triangulated landmarks X (K,3) where ok}; limbs with none left out."""
    index = {int(lm): i for i, lm in enumerate(rig_points.landmarks)}
    out = {}
    for limb, landmarks in LIMB_LANDMARKS.items():
        idx = [index[lm] for lm in landmarks if lm in index and ok[index[lm]]]
        if idx:
            out[limb] = float(np.linalg.norm(world_points[idx] - X[idx], axis=1).max())
    return out


def pose_from_keypoints(body, cameras, targets, rig_points, x_start):
    """A pose for the frame's KeypointTargets: swaps resolved, triangulated, root aligned, then fitted.
    Returns (pose, number of triangulated points, rms residual in metres); the pose is `x_start`
    unchanged when too few landmarks triangulate."""
    X, ok = triangulated_landmarks(cameras, targets, rig_points)
    if ok.sum() < 6:
        return np.array(x_start, float), int(ok.sum()), np.inf
    x = align_root(body, rig_points, np.array(x_start, float), X, ok)
    x, rms = fit_to_points(body, rig_points, x, X, ok)
    return x, int(ok.sum()), rms
