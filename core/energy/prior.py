"""The anatomical prior V_anat (paper eqs. 13-14, algorithms.md 7.5, A16).

Independent Parzen-Rosenblatt densities over groups of joint angles (head, upper body, lower body), each
from the same training poses (200 by default, CMU motion mapped into the body's DOF):
    p_g(x) = 1/(L h^d) sum_l K((x - y_l)/h),  K = standard Gaussian,
    V_anat(x) = -(1/G) sum_g log p_g(x)        (G = 3 groups in the paper: -1/3 log(p_head p_upper p_lower)).
Bandwidth per group: for each sample the distance to its second-nearest *other* sample; h is the maximum
over samples. log p uses log-sum-exp so poses far from all samples stay finite.

Floor [DESIGN]: with few training clips the rule gives some groups a small bandwidth (the head: ~0.2 rad),
and a pose 30 degrees from every sample then costs tens of energy units: more than every image term
together, so the prior, not the images, decides the pose (docs/defaults.md, "AnatomicalPrior.floor_sigmas").
So each group's kernel sum is floored at the value one sample contributes at `floor_sigmas` bandwidths
(default 3): far from all data the prior stays a bounded, flat penalty and stops pulling. floor_sigmas=None
gives eq. 13 as is.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


# Beyond the rig's joint limits a pose is not a person's, however the density is floored: each radian past a limit
# costs (excess / LIMIT_SOFTNESS)^2 x OUTSIDE_LIMIT_COST [DESIGN]. The search and the local fit keep to the limits,
# so this never changes a tracked pose; it makes the prior itself say "impossible" (10 degrees past: about 600,
# against the floored density's few units).
OUTSIDE_LIMIT_COST = 50.0
LIMIT_SOFTNESS = 0.05  # rad


class PriorError(ValueError):
    """Training samples or a saved prior are unusable."""


def second_neighbour_bandwidth(samples):
    """max over samples of the distance to the 2nd-nearest other sample (A16)."""
    y = np.asarray(samples, dtype=np.float64)
    if len(y) < 3:
        raise PriorError(f"a Parzen group needs at least 3 training samples for its bandwidth; got {len(y)}")
    d2 = np.sum((y[:, None, :] - y[None, :, :]) ** 2, axis=-1)
    np.fill_diagonal(d2, np.inf)
    second = np.sqrt(np.sort(d2, axis=1)[:, 1])
    return float(second.max())


def _logsumexp(a, axis):
    m = np.max(a, axis=axis, keepdims=True)
    return np.squeeze(m, axis=axis) + np.log(np.sum(np.exp(a - m), axis=axis))


class AnatomicalPrior:
    def __init__(self, groups, samples, bandwidths, n_dof, floor_sigmas=3.0):
        """groups {name: DOF indices}; samples {name: (L,d)}; bandwidths {name: h}; n_dof = D of the poses;
        floor_sigmas: kernel-sum floor in bandwidths (see the module docstring), None for none."""
        self.floor_sigmas = None if floor_sigmas is None else float(floor_sigmas)
        self.limits = None  # (lower, upper) per DOF once bounded_by: the rig's joint limits
        self.groups = {g: np.asarray(idx, dtype=np.int64) for g, idx in groups.items()}
        self.samples = {g: np.asarray(samples[g], dtype=np.float64) for g in self.groups}
        self._sample_norms = {g: np.sum(y * y, axis=1) for g, y in self.samples.items()}
        self.bandwidths = {g: float(bandwidths[g]) for g in self.groups}
        self.n_dof = int(n_dof)
        if not self.groups:
            raise PriorError("the prior needs at least one DOF group")
        for g, idx in self.groups.items():
            if self.samples[g].ndim != 2 or self.samples[g].shape[1] != len(idx):
                raise PriorError(f"group {g!r}: samples have shape {self.samples[g].shape}; expected (L, {len(idx)})")
            if not self.bandwidths[g] > 0:
                raise PriorError(f"group {g!r}: bandwidth is {self.bandwidths[g]}; the training samples of this "
                                 "group are (nearly) identical: train on more varied motion")
            if len(idx) and (idx.min() < 0 or idx.max() >= self.n_dof):
                raise PriorError(f"group {g!r}: DOF indices {idx.tolist()} outside 0..{self.n_dof - 1}")

    # ---- training --------------------------------------------------------------------------------
    @classmethod
    def fit(cls, samples, groups, n_samples=200, seed=0, floor_sigmas=3.0):
        """Pick n_samples training poses (random, seeded) from samples (L,D) and fit each group's density."""
        y = np.asarray(samples, dtype=np.float64)
        if y.ndim != 2:
            raise PriorError(f"training samples must be a (L, D) array of poses; got shape {y.shape}")
        if not np.all(np.isfinite(y)):
            raise PriorError("training samples contain NaN or infinite values")
        groups = {g: list(idx) for g, idx in groups.items() if len(idx)}
        if len(y) > n_samples:
            y = y[np.sort(np.random.default_rng(seed).choice(len(y), n_samples, replace=False))]
        sub = {g: y[:, idx] for g, idx in groups.items()}
        return cls(groups, sub, {g: second_neighbour_bandwidth(s) for g, s in sub.items()}, y.shape[1],
                   floor_sigmas)

    @classmethod
    def from_motion(cls, body, clips, n_samples=200, seed=0, oversample=2):
        """Train on motion clips (core.mocap MotionClip) mapped into the body's DOF (core.mocap.to_dof).

        Only `oversample` x n_samples frames, spread evenly in time over the clips, are mapped (fitting
        every frame of long clips is slow); `fit` then draws the n_samples training poses from them.
        """
        from ..mocap.to_dof import dof_sequence_from_clip

        if not clips:
            raise PriorError("no motion clips to train the anatomical prior on")
        per_clip = int(np.ceil(oversample * n_samples / len(clips)))
        poses = []
        for clip in clips:
            frames = np.unique(np.linspace(0, clip.n_frames - 1, min(per_clip, clip.n_frames)).round().astype(int))
            result = dof_sequence_from_clip(body, clip, frames=frames)
            poses.append(np.asarray(result[0] if isinstance(result, tuple) else result))
        return cls.fit(np.concatenate(poses), body.prior_groups, n_samples, seed)

    # ---- evaluation ------------------------------------------------------------------------------
    def _check(self, poses):
        x = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        if x.shape[1] != self.n_dof:
            raise PriorError(f"poses have {x.shape[1]} values; the prior was trained on {self.n_dof} DOF")
        return x

    def _group_terms(self, x, g):
        y, h = self.samples[g], self.bandwidths[g]
        diff = x[:, None, self.groups[g]] - y[None]  # (P,L,d)
        a = -np.sum(diff ** 2, axis=-1) / (2 * h * h)
        return diff, a, y, h

    def _exponents(self, x, g):
        """_group_terms' kernel exponents (P,L) alone, from one product: |x - y|^2 = |x|^2 - 2 x.y + |y|^2
        (the (P,L,d) differences cost ten times more, and only the gradient needs them)."""
        y, h = self.samples[g], self.bandwidths[g]
        xg = x[:, self.groups[g]]
        d2 = np.sum(xg * xg, axis=1)[:, None] - 2.0 * (xg @ y.T) + self._sample_norms[g][None, :]
        return -np.maximum(d2, 0.0) / (2 * h * h)

    def log_density(self, poses, group):
        """log p_g(x) for poses (P,D)."""
        x = self._check(poses)
        a, y, h = self._exponents(x, group), self.samples[group], self.bandwidths[group]
        L, d = y.shape
        return self._floored(_logsumexp(a, axis=1)) - np.log(L) - d * np.log(h) - 0.5 * d * np.log(2 * np.pi)

    def _floored(self, kernel_log_sum):
        if self.floor_sigmas is None:
            return kernel_log_sum
        return np.maximum(kernel_log_sum, -0.5 * self.floor_sigmas ** 2)

    def bounded_by(self, lower, upper):
        """This prior with the rig's joint limits (D,) each: a pose beyond them costs OUTSIDE_LIMIT_COST per
        (excess / LIMIT_SOFTNESS)^2. Returns self."""
        lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
        if lower.shape != (self.n_dof,) or upper.shape != (self.n_dof,) or np.any(lower > upper):
            raise PriorError(f"joint limits must be {self.n_dof} lower and upper values, lower <= upper")
        self.limits = (lower, upper)
        return self

    def _excess(self, x):
        """(P,D) signed radians past the limits (0 within them)."""
        if self.limits is None:
            return np.zeros_like(x)
        lower, upper = self.limits
        return np.where(x < lower, x - lower, np.where(x > upper, x - upper, 0.0))

    def energy(self, poses):
        """V_anat = -(1/G) sum_g log p_g(x), (P,), plus the cost of any joint past its limit."""
        x = self._check(poses)
        density = -sum(self.log_density(x, g) for g in self.groups) / len(self.groups)
        return density + OUTSIDE_LIMIT_COST * np.sum((self._excess(x) / LIMIT_SOFTNESS) ** 2, axis=1)

    def gradient(self, poses):
        """dV_anat/dx (P,D): per group (x - weighted mean of the samples) / h^2 / G (mean-shift form)."""
        x = self._check(poses)
        grad = np.zeros_like(x)
        for g, idx in self.groups.items():
            _, a, y, h = self._group_terms(x, g)
            w = np.exp(a - a.max(axis=1, keepdims=True))
            w /= w.sum(axis=1, keepdims=True)
            active = (self._floored(_logsumexp(a, axis=1)) == _logsumexp(a, axis=1))[:, None]  # flat where floored
            grad[:, idx] += np.where(active, (x[:, idx] - w @ y) / (h * h), 0.0)
        return grad / len(self.groups) + 2.0 * OUTSIDE_LIMIT_COST * self._excess(x) / LIMIT_SOFTNESS ** 2

    # ---- persistence -----------------------------------------------------------------------------
    def save(self, path):
        data = {"group_names": np.array(list(self.groups)), "n_dof": np.array(self.n_dof),
                "floor_sigmas": np.array(np.nan if self.floor_sigmas is None else self.floor_sigmas)}
        if self.limits is not None:
            data["lower"], data["upper"] = self.limits
        for i, g in enumerate(self.groups):
            data[f"indices_{i}"] = self.groups[g]
            data[f"samples_{i}"] = self.samples[g]
            data[f"bandwidth_{i}"] = np.array(self.bandwidths[g])
        np.savez(Path(path), **data)

    @classmethod
    def load(cls, path):
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"anatomical prior file {path} does not exist; train one with "
                                    "AnatomicalPrior.from_motion(body, clips).save(path)")
        try:
            with np.load(path, allow_pickle=False) as f:
                names = [str(n) for n in f["group_names"]]
                groups = {g: f[f"indices_{i}"] for i, g in enumerate(names)}
                samples = {g: f[f"samples_{i}"] for i, g in enumerate(names)}
                bw = {g: float(f[f"bandwidth_{i}"]) for i, g in enumerate(names)}
                n_dof = int(f["n_dof"])
                floor = float(f["floor_sigmas"]) if "floor_sigmas" in f.files else np.nan
                limits = (f["lower"], f["upper"]) if "lower" in f.files else None
        except (KeyError, ValueError, OSError) as exc:
            raise PriorError(f"{path} is not a saved anatomical prior ({exc}); re-train and save it") from exc
        prior = cls(groups, samples, bw, n_dof, None if np.isnan(floor) else floor)
        return prior if limits is None else prior.bounded_by(*limits)
