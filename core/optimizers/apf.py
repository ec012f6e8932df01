"""Annealed Particle Filter (APF), the local multi-hypothesis optimiser (algorithms.md 3).

Per frame: M layers of resample + Gaussian diffusion + weighting, where each layer's beta is solved
so that the survival rate (normalised ESS) of the weights equals alpha (0.5). The weighted set of
the last layer carries over to the next frame.
"""
from __future__ import annotations

import math

import numpy as np

from .base import (RESAMPLERS, CountingEnergy, Optimizer, OptimizerInputError, PoseSpace, boltzmann_weights,
                   gaussian_mutation, particle_sets, weighted_covariance)
from .dynamics import checked_dynamics, predicted_displacement


def survival_rate(V: np.ndarray, beta: float) -> float:
    """alpha(beta) = (sum w)^2 / (N sum w^2) with w = exp(-beta (V - Vmin))."""
    g, _ = boltzmann_weights(V, beta)
    return float(g.sum() ** 2 / (V.shape[0] * (g @ g)))


def solve_beta(V: np.ndarray, alpha: float, lo: float = 1e-12, hi: float = 1e12,
               tol: float = 1e-4, max_iter: int = 200) -> tuple[float, bool]:
    """beta with survival_rate(V, beta) = alpha, by bisection on log beta.

    alpha(beta) falls monotonically from 1 to (#minima)/N. Returns (beta, solved); when alpha is
    out of reach (all energies equal, or alpha below (#minima)/N) the nearest end of the bracket is
    returned with solved=False.
    """
    if survival_rate(V, lo) < alpha:
        return lo, False
    if survival_rate(V, hi) > alpha:
        return hi, False
    a, b = math.log(lo), math.log(hi)
    for _ in range(max_iter):
        mid = 0.5 * (a + b)
        r = survival_rate(V, math.exp(mid))
        if abs(r - alpha) < tol:
            return math.exp(mid), True
        if r > alpha:
            a = mid
        else:
            b = mid
    return math.exp(0.5 * (a + b)), True


class AnnealedParticleFilter(Optimizer):
    """APF (algorithms.md 3.1-3.2). Defaults: N=200, M=budget//N=15 layers, alpha=0.5, adaptive covariance.

    covariance: "adaptive" -> P_m = alpha * Cov_w + diag(floor^2); the first layer of a frame adds
    diag(sigma_pred^2) (DESIGN: the same inter-frame spread as ISA, otherwise a concentrated set
    cannot follow motion). "fixed" -> P_m = alpha^(layer) * P0 + floor, P0 = diag((p0_scale*s)^2),
    broadest in the first layer.

    velocity: shift the carried-over set by the predicted displacement between frames, the same
    prediction as ISA's (the mean of `dynamics`, an AR(3) model, when given; else constant velocity).
    """
    name = "apf"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, *, n: int = 200,
                 M: int | None = None, alpha: float = 0.5, covariance: str = "adaptive", sigma_floor=None,
                 sigma_pred=None, p0_scale: float = 1.0, resampling: str = "multinomial",
                 estimate: str = "mean", init_spread: float = 0.5, velocity: bool = False, dynamics=None,
                 **params):
        super().__init__(space, budget, seed, **params)
        self.velocity = bool(velocity)
        self.dynamics = checked_dynamics(dynamics, "APF")
        self.n, self.M = particle_sets(self, n, M, budget, "APF", "layer")
        if not 0 < alpha < 1:
            raise OptimizerInputError(f"APF survival rate alpha must lie in (0, 1), got {alpha}")
        if covariance not in ("adaptive", "fixed"):
            raise OptimizerInputError(f"APF covariance must be 'adaptive' or 'fixed', got {covariance!r}")
        if resampling not in RESAMPLERS:
            raise OptimizerInputError(f"APF resampling must be one of {sorted(RESAMPLERS)}, got {resampling!r}")
        if estimate not in ("mean", "best"):
            raise OptimizerInputError(f"APF estimate must be 'mean' or 'best', got {estimate!r}")
        d = space.dim
        self.alpha, self.covariance, self.resampling = float(alpha), covariance, resampling
        self.sigma_floor = space.default_floor() if sigma_floor is None else np.broadcast_to(
            np.asarray(sigma_floor, float), (d,)).copy()
        self.sigma_pred = 0.5 * space.scale if sigma_pred is None else np.broadcast_to(
            np.asarray(sigma_pred, float), (d,)).copy()
        self.P0 = np.diag((float(p0_scale) * space.scale) ** 2)
        self.estimate_mode, self.init_spread = estimate, float(init_spread)
        self.state: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def search_budget(self) -> int:
        return self.n * self.M

    def _reset(self) -> None:
        self.state = None

    pose_arrays = ("x0", "particles")

    def _carried_arrays(self):
        return {} if self.state is None else {"particles": self.state[0], "weights": self.state[1]}

    def _restore_carried(self, arrays):
        self.state = None if "particles" not in arrays else (np.asarray(arrays["particles"], dtype=float),
                                                             np.asarray(arrays["weights"], dtype=float))

    def _initial_set(self, history):
        centre = history[-1] if history else self.x0
        std = self.init_spread * self.space.scale
        d = self.space.dim
        X = self.space.sample_within_limits(
            lambda rows, g: centre + g.standard_normal((rows.shape[0], d)) * std, self.rng, self.n)
        return X, np.full(self.n, 1.0 / self.n)

    def _search(self, energy: CountingEnergy, history):
        X, pi = self.state if self.state is not None else self._initial_set(history)
        if self.state is not None and self.velocity:   # the same prediction as ISA's
            shift = predicted_displacement(history, self.dynamics)
            X = X if shift is None else X + shift
        resample = RESAMPLERS[self.resampling]
        floor_cov = np.diag(self.sigma_floor ** 2)
        betas, rates, unsolved = [], [], 0
        for layer in range(self.M):              # layer 0 is the broadest (the spec's layer M)
            idx = resample(pi, self.n, self.rng)
            if self.covariance == "adaptive":
                cov = self.alpha * weighted_covariance(X, pi) + floor_cov
                if layer == 0:
                    cov = cov + np.diag(self.sigma_pred ** 2)
            else:
                cov = self.alpha ** layer * self.P0 + floor_cov
            X = gaussian_mutation(self.space, X[idx], cov, self.rng)
            V = energy(X)
            beta, ok = solve_beta(V, self.alpha)
            unsolved += not ok
            _, pi = boltzmann_weights(V, beta)
            betas.append(beta)
            rates.append(survival_rate(V, beta))
        self.state = (X, pi)
        est = X[np.argmax(pi)].copy() if self.estimate_mode == "best" else self.space.clamp(pi @ X)
        info = {"betas": betas, "survival_rates": rates, "unsolved_layers": unsolved, "layers": self.M,
                "particles": self.n, "covariance": self.covariance}
        return est, info
