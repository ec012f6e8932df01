"""Which of a frame's landmarks belong to someone else: the single-person landmark model, run on a crop around this
actor, returns whoever is most visible in it, and where another person stands in front of the actor in one view
that view's landmarks are that person's. Across views the actor's landmarks meet in one 3D point; another
person's do not meet the actor's. Per landmark, every pair of views proposes a 3D point (and the predicted pose
proposes one); the point most views agree with wins, a view's landmark far from it is set aside
(docs/how-it-tracks.md, "Other people in the room").
"""
from itertools import combinations

import numpy as np

from .keypoint_fit import MIN_WEIGHT, dlt_batched, resolve_swaps_with_projections

# a view agrees with a 3D point when its landmark lies within this share of the person's size in that view of the
# point's projection [DESIGN] (docs/defaults.md, "Landmarks another person gave")
AGREE_SHARE = 0.06
# the predicted point supports a proposal within this distance (metres): it breaks a tie of two views against two
PREDICTION_SUPPORT_M = 0.25
# a view that loses more than this share of its landmarks' weight loses all of them: the rest is that person's too
# [DESIGN] (docs/defaults.md, "Several actors: a shared view")
VIEW_TAKEN_SHARE = 0.5
# a landmark is judged only when its winner has this many votes (views agreeing, plus the prediction's)
MIN_VOTES = 3


def disagreeing_landmarks(cameras, uv, weight, person_px, swap, predicted=None, agree_share=None):
    """(C,K) bool: the landmarks (weight > 0) that disagree with the point most views agree on.

    uv (C,K,2) pixels, weight (C,K), person_px (C,), swap (K,) the left/right partner of each point,
    predicted (K,3) this actor's predicted points (world metres) or None. Left/right swaps are resolved
    first (a swapped view is one view seeing the same person)."""
    C, K = weight.shape
    agree_share = AGREE_SHARE if agree_share is None else agree_share
    if C < 3:
        return np.zeros((C, K), bool)
    resolved_uv, resolved_w, P, ideal = resolve_swaps_with_projections(cameras, uv, weight, swap)
    seen = resolved_w >= MIN_WEIGHT
    tol = agree_share * np.asarray(person_px, dtype=np.float64)[:, None]
    proposals = []
    for i, j in combinations(range(C), 2):
        pair = np.zeros_like(resolved_w)
        pair[[i, j]] = resolved_w[[i, j]]
        X, ok = dlt_batched(P, ideal, pair, MIN_WEIGHT)
        proposals.append(np.where(ok[:, None], X, np.nan))
    if predicted is not None:
        proposals.append(np.asarray(predicted, dtype=np.float64))
    best_votes = np.zeros(K)
    best_near = np.full(K, np.inf)
    best_agree = np.zeros((C, K), bool)
    for X in proposals:
        finite = np.all(np.isfinite(X), axis=1)
        Xs = np.where(finite[:, None], X, 0.0)
        agree = np.zeros((C, K), bool)
        for c, cam in enumerate(cameras):
            depth = (Xs @ cam.R.T + cam.t)[:, 2]
            r = np.linalg.norm(cam.project(Xs) - resolved_uv[c], axis=1)
            agree[c] = seen[c] & finite & (depth > 0) & (r <= tol[c])
        near = (np.linalg.norm(Xs - predicted, axis=1) if predicted is not None else np.full(K, np.inf))
        near = np.where(finite, near, np.inf)
        votes = agree.sum(axis=0) + (near <= PREDICTION_SUPPORT_M)
        better = (votes > best_votes) | ((votes == best_votes) & (near < best_near))
        best_votes = np.where(better, votes, best_votes)
        best_near = np.where(better, near, best_near)
        best_agree = np.where(better[None], agree, best_agree)
    judged = best_votes >= MIN_VOTES
    out_resolved = seen & ~best_agree & judged[None]
    # back to the views' own sides: a view whose pair was swapped set aside the partner's landmark
    swapped = ~np.all(resolved_uv == uv, axis=-1)
    partner = np.where(swapped, np.asarray(swap)[None, :], np.arange(K)[None, :])
    out = np.zeros((C, K), bool)
    rows = np.arange(C)[:, None]
    out[rows, partner] = out_resolved
    return out & (weight > 0)


def without_landmarks(targets, out, taken_share=VIEW_TAKEN_SHARE):
    """KeypointTargets without the landmarks `out` (C,K) marks, and (C,) bool the views that lost more than
    `taken_share` of their weight so: those lose all of theirs (someone else holds that view's crop)."""
    total = targets.weight.sum(axis=1)
    share = np.divide((targets.weight * out).sum(axis=1), total, out=np.zeros_like(total), where=total > 0)
    taken = share > taken_share
    weight = np.where(out | taken[:, None], 0.0, targets.weight)
    return type(targets)(targets.uv, weight, targets.person_px, targets.alt_uv, targets.alt_cost), taken


def set_aside_disagreeing(cameras, targets, swap, predicted=None):
    """KeypointTargets without the landmarks the views disagree with, (C,K) bool which, and (C,) bool the views
    that lost most of their weight so (those lose all of theirs)."""
    out = disagreeing_landmarks(cameras, targets.uv, targets.weight, targets.person_px, swap, predicted)
    kept, taken = without_landmarks(targets, out)
    return kept, out, taken
