"""Autoregressive motion models as conditional Gaussians p(x_t | x_{t-1}, x_{t-2}, x_{t-3}).

algorithms.md 4.4: the fallbacks of the GP-AR(3): damped constant velocity and a per-DOF linear
AR(3) fitted by least squares. Both are batched over particles: inputs (P, D), outputs
(mean (P, D), std (P, D)), so the PF code does not depend on which model is used.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Sequence

import numpy as np

from .base import OptimizerInputError


class ConditionalGaussianDynamics(ABC):
    order = 3

    @abstractmethod
    def predict(self, x1: np.ndarray, x2: np.ndarray, x3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and per-DOF standard deviation of x_t given x_{t-1}=x1, x_{t-2}=x2, x_{t-3}=x3."""

    def predict_from_history(self, history: Sequence[np.ndarray]) -> np.ndarray:
        """Mean prediction from a list of estimates (most recent last); shorter lists repeat the oldest."""
        if not history:
            raise OptimizerInputError("dynamics need at least one previous pose to predict from")
        h = [np.asarray(history[max(len(history) - k, 0)], float) for k in (1, 2, 3)]
        mean, _ = self.predict(h[0][None], h[1][None], h[2][None])
        return mean[0]


def checked_dynamics(dynamics, who: str):
    """`dynamics` if it can predict from a history of estimates (or None), else a clear error."""
    if dynamics is not None and not hasattr(dynamics, "predict_from_history"):
        raise OptimizerInputError(f"{who} dynamics must be a ConditionalGaussianDynamics (predict_from_history)")
    return dynamics


def predicted_displacement(history: Sequence[np.ndarray],
                           dynamics: ConditionalGaussianDynamics | None) -> np.ndarray | None:
    """How far the next pose is predicted to move from the last estimate: the mean of `dynamics`
    (AR(3)) when given, else constant velocity; None before two estimates exist."""
    if len(history) < 2:
        return None
    if dynamics is not None:
        return dynamics.predict_from_history(history) - np.asarray(history[-1], float)
    return np.asarray(history[-1], float) - np.asarray(history[-2], float)


def _per_dof(name: str, value, d: int | None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim > 1 or (d is not None and arr.ndim == 1 and arr.shape[0] != d):
        raise OptimizerInputError(f"{name} must be a scalar or a per-DOF vector of length {d}")
    return arr


class DampedConstantVelocity(ConditionalGaussianDynamics):
    """x_t = x_{t-1} + gamma (x_{t-1} - x_{t-2}) + N(0, diag(sigma^2)); sigma scalar or (D,)."""

    def __init__(self, gamma: float = 0.8, sigma=0.01):
        if not 0.0 <= gamma <= 1.0:
            raise OptimizerInputError(f"damping gamma must lie in [0, 1], got {gamma}")
        self.gamma = float(gamma)
        self.sigma = _per_dof("sigma", sigma, None)
        if np.any(self.sigma < 0):
            raise OptimizerInputError("dynamics sigma must be >= 0")

    def predict(self, x1, x2, x3):
        mean = x1 + self.gamma * (x1 - x2)
        return mean, np.broadcast_to(self.sigma, mean.shape)


class LinearAR3(ConditionalGaussianDynamics):
    """Per DOF d: x_t = a1 x_{t-1} + a2 x_{t-2} + a3 x_{t-3} + c + e, e ~ N(0, sigma_d^2)."""

    def __init__(self, coeffs: np.ndarray, offset: np.ndarray, sigma: np.ndarray):
        self.coeffs = np.asarray(coeffs, dtype=float)          # (D, 3): a1, a2, a3
        d = self.coeffs.shape[0]
        if self.coeffs.shape != (d, 3):
            raise OptimizerInputError(f"AR(3) coefficients must have shape (D, 3), got {self.coeffs.shape}")
        self.offset = _per_dof("offset", offset, d) * np.ones(d)
        self.sigma = _per_dof("sigma", sigma, d) * np.ones(d)

    @classmethod
    def fit(cls, sequences: Sequence[np.ndarray], min_sigma: float = 0.0) -> "LinearAR3":
        """Least squares per DOF over all (T, D) sequences (T >= 4 each); sigma = residual std (dof-corrected)."""
        seqs = [np.asarray(s, dtype=float) for s in sequences]
        if not seqs:
            raise OptimizerInputError("LinearAR3.fit needs at least one (T, D) training sequence")
        d = seqs[0].shape[1] if seqs[0].ndim == 2 else -1
        rows_in, rows_out = [], []
        for i, s in enumerate(seqs):
            if s.ndim != 2 or s.shape[1] != d:
                raise OptimizerInputError(f"sequence {i} has shape {s.shape}; every sequence must be (T, {d})")
            if not np.all(np.isfinite(s)):
                raise OptimizerInputError(f"sequence {i} contains NaN/inf: clean or drop those frames")
            if s.shape[0] < 4:
                continue                                        # too short to give one AR(3) sample
            rows_in.append(np.stack([s[2:-1], s[1:-2], s[:-3]], axis=-1))   # (T-3, D, 3)
            rows_out.append(s[3:])
        if not rows_in:
            raise OptimizerInputError("LinearAR3.fit: every sequence is shorter than 4 frames")
        Z = np.concatenate(rows_in)            # (N, D, 3)
        Y = np.concatenate(rows_out)           # (N, D)
        n = Y.shape[0]
        if n < 5:
            raise OptimizerInputError(f"LinearAR3.fit: only {n} training samples, need at least 5")
        coeffs = np.empty((d, 3))
        offset = np.empty(d)
        sigma = np.empty(d)
        ones = np.ones((n, 1))
        for j in range(d):
            A = np.hstack([Z[:, j, :], ones])
            sol, *_ = np.linalg.lstsq(A, Y[:, j], rcond=None)
            resid = Y[:, j] - A @ sol
            coeffs[j], offset[j] = sol[:3], sol[3]
            sigma[j] = np.sqrt(resid @ resid / max(n - 4, 1))
        return cls(coeffs, offset, np.maximum(sigma, min_sigma))

    def predict(self, x1, x2, x3):
        a = self.coeffs
        mean = a[:, 0] * x1 + a[:, 1] * x2 + a[:, 2] * x3 + self.offset
        return mean, np.broadcast_to(self.sigma, mean.shape)
