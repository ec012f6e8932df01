"""Standard particle filter (SIR) with autoregressive dynamics (algorithms.md 4).

Each particle carries its own history (x_{t-1}, x_{t-2}, x_{t-3}); one frame is resample ->
predict from the conditional Gaussian dynamics -> weight exp(-beta_pf V). The whole budget
(N = 3000) is spent in a single batched energy call.
"""
from __future__ import annotations

import numpy as np

from .base import RESAMPLERS, CountingEnergy, Optimizer, OptimizerInputError, PoseSpace, boltzmann_weights
from .dynamics import ConditionalGaussianDynamics, DampedConstantVelocity


class ParticleFilter(Optimizer):
    """PF (algorithms.md 4.1-4.2). Defaults: N = budget = 3000, damped constant velocity
    (gamma 0.8, sigma 0.5 s), kappa = 1, beta_pf = 1, systematic resampling every frame.

    resample_threshold: resample only when ESS/N falls below it (1.0 = every frame).
    """
    name = "pf"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, *,
                 dynamics: ConditionalGaussianDynamics | None = None, kappa: float = 1.0, beta_pf: float = 1.0,
                 resampling: str = "systematic", resample_threshold: float = 1.0, estimate: str = "mean",
                 init_spread: float = 0.5, **params):
        super().__init__(space, budget, seed, **params)
        self.n = self.budget
        if self.n < 2:
            raise OptimizerInputError("the PF needs a budget of at least 2 particles")
        if dynamics is None:
            dynamics = DampedConstantVelocity(0.8, 0.5 * space.scale)
        if not isinstance(dynamics, ConditionalGaussianDynamics):
            raise OptimizerInputError("dynamics must be a ConditionalGaussianDynamics (e.g. DampedConstantVelocity, "
                                      "LinearAR3.fit(sequences))")
        if kappa <= 0 or beta_pf <= 0:
            raise OptimizerInputError("PF needs kappa > 0 and beta_pf > 0")
        if resampling not in RESAMPLERS:
            raise OptimizerInputError(f"PF resampling must be one of {sorted(RESAMPLERS)}, got {resampling!r}")
        if estimate not in ("mean", "best"):
            raise OptimizerInputError(f"PF estimate must be 'mean' or 'best', got {estimate!r}")
        self.dynamics, self.kappa, self.beta_pf = dynamics, float(kappa), float(beta_pf)
        self.resampling, self.resample_threshold = resampling, float(resample_threshold)
        self.estimate_mode, self.init_spread = estimate, float(init_spread)
        self.hist: np.ndarray | None = None      # (N, 3, D): x_{t-1}, x_{t-2}, x_{t-3}
        self.w: np.ndarray | None = None

    def _reset(self) -> None:
        self.hist, self.w = None, None

    pose_arrays = ("x0", "history")

    def _carried_arrays(self):
        return {} if self.hist is None else {"history": self.hist, "weights": self.w}

    def _restore_carried(self, arrays):
        if "history" not in arrays:
            self.hist, self.w = None, None
        else:
            self.hist, self.w = np.asarray(arrays["history"], dtype=float), np.asarray(arrays["weights"], dtype=float)

    def _init_particles(self, history):
        # One noisy pose per particle copied into all three history slots: zero initial velocity.
        centre = history[-1] if history else self.x0
        std, d = self.init_spread * self.space.scale, self.space.dim
        X = self.space.sample_within_limits(
            lambda rows, g: centre + g.standard_normal((rows.shape[0], d)) * std, self.rng, self.n)
        self.hist = np.repeat(X[:, None, :], 3, axis=1)
        self.w = np.full(self.n, 1.0 / self.n)

    def _search(self, energy: CountingEnergy, history):
        if self.hist is None:
            self._init_particles(history)
        ess = 1.0 / (self.n * float(self.w @ self.w))
        resampled = ess < self.resample_threshold or self.resample_threshold >= 1.0
        if resampled:
            idx = RESAMPLERS[self.resampling](self.w, self.n, self.rng)
            self.hist, self.w = self.hist[idx], np.full(self.n, 1.0 / self.n)
        H = self.hist
        mean, std = self.dynamics.predict(H[:, 0], H[:, 1], H[:, 2])
        std = np.sqrt(self.kappa) * std
        d = self.space.dim
        X = self.space.sample_within_limits(
            lambda rows, g: mean[rows] + g.standard_normal((rows.shape[0], d)) * std[rows], self.rng, self.n)
        V = energy(X)
        _, lik = boltzmann_weights(V, self.beta_pf)
        w = self.w * lik
        total = w.sum()
        w = w / total if total > 0 else lik      # old weights underflowed: fall back to the likelihood
        self.w = w
        self.hist = np.concatenate([X[:, None, :], H[:, :2]], axis=1)
        est = X[np.argmax(w)].copy() if self.estimate_mode == "best" else self.space.clamp(w @ X)
        info = {"ess_fraction": 1.0 / (self.n * float(w @ w)), "resampled": bool(resampled), "particles": self.n}
        return est, info
