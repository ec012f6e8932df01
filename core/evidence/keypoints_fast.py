"""The keypoint term in numba: core.evidence.keypoints.keypoint_energy (the NumPy reference) in one pass per pose,
without its (P,C,K,1+A,2) temporaries, argmins and the second pass for the swapped assignment.

The search calls it for every batch of poses on the main thread while the other core waits: the NumPy
version cost ~2.7 ms a batch (43 ms a frame at the paper's budget), this one a tenth of that."""
import numpy as np

from ..jit import jit


@jit()
def _rho(px, py, uv, extra, c, m, inv_s2):
    """The cheapest of landmark m's candidates in view c for a point at (px, py), each capped at 1."""
    best = 1.0
    for a in range(uv.shape[2]):
        dx, dy = px - uv[c, m, a, 0], py - uv[c, m, a, 1]
        d2 = (dx * dx + dy * dy) * inv_s2
        r = d2 / (d2 + 1.0) + extra[c, m, a]
        if r < best:
            best = r
    return best


@jit()
def _energy_kernel(projected, uv, extra, weight, inv_s2, swap, total_w, out):
    P, C, K = projected.shape[0], projected.shape[1], projected.shape[2]
    n_seen = 0
    for c in range(C):
        if total_w[c] > 1e-6:
            n_seen += 1
    for p in range(P):
        total = 0.0
        for c in range(C):
            if total_w[c] <= 1e-6:
                continue
            view = 0.0
            for k in range(K):
                j = swap[k]
                if j < k:
                    continue  # the pair was counted with its first point
                xk, yk = projected[p, c, k, 0], projected[p, c, k, 1]
                same_k = weight[c, k] * _rho(xk, yk, uv, extra, c, k, inv_s2[c])
                if j == k:  # no left/right partner (the nose)
                    view += same_k
                    continue
                xj, yj = projected[p, c, j, 0], projected[p, c, j, 1]
                same = same_k + weight[c, j] * _rho(xj, yj, uv, extra, c, j, inv_s2[c])
                swapped = (weight[c, j] * _rho(xk, yk, uv, extra, c, j, inv_s2[c])
                           + weight[c, k] * _rho(xj, yj, uv, extra, c, k, inv_s2[c]))
                view += swapped if swapped < same else same
            total += view / total_w[c]
        out[p] = total / n_seen if n_seen else 0.0


def keypoint_energy(projected, targets, swap, sigma):
    """Same arguments and result as core.evidence.keypoints.keypoint_energy: (P,C,K,2) -> (P,)."""
    uv, extra = targets.candidates()
    out = np.empty(projected.shape[0])
    _energy_kernel(np.ascontiguousarray(projected, dtype=np.float64), np.ascontiguousarray(uv, dtype=np.float64),
                   np.ascontiguousarray(extra, dtype=np.float64), np.ascontiguousarray(targets.weight, np.float64),
                   (1.0 / (sigma * np.asarray(targets.person_px, np.float64))) ** 2,
                   np.ascontiguousarray(swap, dtype=np.int64), targets.weight.sum(axis=1).astype(np.float64), out)
    return out
