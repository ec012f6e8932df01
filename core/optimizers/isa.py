"""Interacting Simulated Annealing (ISA), the default global optimiser (algorithms.md 2).

Per frame: M rounds of Boltzmann-Gibbs weighting with an increasing beta, epsilon-selection
(eps = 1/max g: each particle is kept with probability g/max g, else replaced by a draw from pi,
so the best particle always survives) and a Gaussian mutation whose covariance is c times the
sample covariance of the selected particles plus a floor ("dynamic variance scheme").
"""
from __future__ import annotations

import math

import numpy as np

from .base import (CountingEnergy, FrameResult, Optimizer, OptimizerInputError, PoseSpace, boltzmann_weights,
                   gaussian_mutation, particle_sets, systematic_resample, weighted_covariance)
from .dynamics import checked_dynamics, predicted_displacement


def epsilon_select(X: np.ndarray, g: np.ndarray, pi: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """ISA selection with eps = 1/max g: keep X[i] with probability g[i]/max g, else draw j ~ pi.

    Returns the selected indices. The particle(s) with g = max g are always kept.
    """
    n = X.shape[0]
    keep = rng.random(n) * g.max() <= g
    idx = np.arange(n)
    redraw = np.flatnonzero(~keep)
    if redraw.size:
        cdf = np.cumsum(pi)
        cdf[-1] = 1.0
        idx[redraw] = np.minimum(np.searchsorted(cdf, rng.random(redraw.size), side="right"), n - 1)
    return idx


def ess_fraction(V: np.ndarray, beta: float) -> float:
    """Normalised effective sample size 1/(n sum pi^2) of exp(-beta V)."""
    _, pi = boltzmann_weights(V, beta)
    return 1.0 / (V.shape[0] * float(pi @ pi))


def beta_for_ess(V: np.ndarray, target: float, lo: float = 1e-10, hi: float = 1e10,
                 tol: float = 1e-4, max_iter: int = 200) -> float | None:
    """beta with ESS/n = target by bisection on log beta; None when the target is not bracketed
    (e.g. all energies equal, so ESS/n = 1 for every beta)."""
    if ess_fraction(V, hi) > target or ess_fraction(V, lo) < target:
        return None
    a, b = math.log(lo), math.log(hi)
    for _ in range(max_iter):
        mid = 0.5 * (a + b)
        e = ess_fraction(V, math.exp(mid))
        if abs(e - target) < tol:
            return math.exp(mid)
        if e > target:
            a = mid
        else:
            b = mid
    return math.exp(0.5 * (a + b))


class InteractingSimulatedAnnealing(Optimizer):
    """ISA (algorithms.md 2.2-2.6). Defaults: n=200, M=budget//n=15, beta_m = 8 (m+1)^0.7, c=0.5.

    velocity: shift the kept particles by the predicted displacement between frames: the mean of
    `dynamics` (an AR(3) model, ConditionalGaussianDynamics) when given, as the paper predicts from the
    previous estimates with its 3rd-order autoregression; else constant velocity.

    schedule: "polynomial" (fixed beta0 (m+1)^b) or "ess" (beta by bisection so that ESS/n falls
    linearly from ess_start to ess_end; when bisection cannot bracket the target, the polynomial
    value is used and counted in info["ess_fallbacks"]; beta is kept non-decreasing).
    elitist: the best selected particle skips the mutation (DESIGN addition), which makes the
    minimum energy of the particle set non-increasing over iterations; the plain algorithm
    mutates every particle, so set elitist=False for it.
    """
    name = "isa"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, *, n: int = 200,
                 M: int | None = None, beta0: float = 8.0, b: float = 0.7, schedule: str = "polynomial",
                 ess_start: float = 0.5, ess_end: float = 0.1, c: float = 0.5, sigma_floor=None,
                 c_pred: float = 1.0, sigma_pred=None, velocity: bool = False, estimate: str = "mean",
                 covariance: str = "full", init_spread: float = 0.5, elitist: bool = True, dynamics=None,
                 **params):
        super().__init__(space, budget, seed, **params)
        self.n, self.M = particle_sets(self, n, M, budget, "ISA", "iteration")
        if schedule not in ("polynomial", "ess"):
            raise OptimizerInputError(f"ISA schedule must be 'polynomial' or 'ess', got {schedule!r}")
        if estimate not in ("mean", "best"):
            raise OptimizerInputError(f"ISA estimate must be 'mean' or 'best', got {estimate!r}")
        if covariance not in ("full", "diag"):
            raise OptimizerInputError(f"ISA covariance must be 'full' or 'diag', got {covariance!r}")
        if beta0 <= 0 or c < 0 or c_pred < 0:
            raise OptimizerInputError("ISA needs beta0 > 0, c >= 0 and c_pred >= 0")
        if not (0 < ess_end <= 1 and 0 < ess_start <= 1):
            raise OptimizerInputError("ESS targets must lie in (0, 1]")
        self.beta0, self.b, self.schedule = float(beta0), float(b), schedule
        self.ess_start, self.ess_end = float(ess_start), float(ess_end)
        self.c, self.c_pred = float(c), float(c_pred)
        d = space.dim
        self.sigma_floor = space.default_floor() if sigma_floor is None else np.broadcast_to(
            np.asarray(sigma_floor, float), (d,)).copy()
        self.sigma_pred = 0.5 * space.scale if sigma_pred is None else np.broadcast_to(
            np.asarray(sigma_pred, float), (d,)).copy()
        self.velocity, self.estimate_mode, self.covariance = bool(velocity), estimate, covariance
        self.init_spread, self.elitist = float(init_spread), bool(elitist)
        self.dynamics = checked_dynamics(dynamics, "ISA")
        self.particles: np.ndarray | None = None

    @property
    def search_budget(self) -> int:
        return self.n * self.M

    def _reset(self) -> None:
        self.particles = None

    pose_arrays = ("x0", "particles")

    def _carried_arrays(self):
        return {} if self.particles is None else {"particles": self.particles}

    def _restore_carried(self, arrays):
        particles = arrays.get("particles")
        self.particles = None if particles is None else np.asarray(particles, dtype=float)

    # ------------------------------------------------------------------ one annealing run
    def polynomial_beta(self, m: int) -> float:
        return self.beta0 * (m + 1) ** self.b

    def _anneal(self, energy: CountingEnergy, X: np.ndarray, M: int,
                schedule: str) -> tuple[np.ndarray, np.ndarray, dict]:
        """M weightings with M-1 selection+mutation steps in between, beta by `schedule`; returns (X, pi, info)."""
        n, d = X.shape
        floor_cov = np.diag(self.sigma_floor ** 2)
        betas, vmins, fallbacks = [], [], 0
        beta_prev = 0.0
        for m in range(M):
            V = energy(X)
            beta = self.polynomial_beta(m)
            if schedule == "ess":
                target = self.ess_start + (self.ess_end - self.ess_start) * (m / max(M - 1, 1))
                solved = beta_for_ess(V, target)
                if solved is None:
                    fallbacks += 1
                else:
                    beta = solved
                beta = max(beta, beta_prev)      # annealing must not cool back down
            beta_prev = beta
            g, pi = boltzmann_weights(V, beta)
            betas.append(beta)
            vmins.append(float(V.min()))
            if m == M - 1:
                break
            idx = epsilon_select(X, g, pi, self.rng)
            Xs = X[idx]
            cov = weighted_covariance(Xs)
            if self.covariance == "diag":
                cov = np.diag(np.diag(cov))
            X = gaussian_mutation(self.space, Xs, self.c * cov + floor_cov, self.rng)
            if self.elitist:
                j = int(np.argmin(V[idx]))      # eps-selection kept the best, so V[idx][j] = min V
                X[j] = Xs[j]
        info = {"betas": betas, "min_energy_per_iteration": vmins, "ess_fallbacks": fallbacks,
                "final_ess_fraction": 1.0 / (n * float(pi @ pi)), "iterations": M, "particles": n}
        return X, pi, info

    def _estimate(self, X: np.ndarray, pi: np.ndarray) -> np.ndarray:
        if self.estimate_mode == "best":
            return X[np.argmax(pi)].copy()
        return self.space.clamp(pi @ X)

    def _keep(self, X: np.ndarray, pi: np.ndarray, n: int) -> np.ndarray:
        """Particles for the next frame: one more eps-selection (or systematic resampling to size n)."""
        g = pi / pi.max()
        if X.shape[0] == n:
            return X[epsilon_select(X, g, pi, self.rng)]
        return X[systematic_resample(pi, n, self.rng)]

    # ------------------------------------------------------------------ initial distribution
    def _initial_particles(self, history: list[np.ndarray]) -> np.ndarray:
        n, d = self.n, self.space.dim
        if self.particles is None:
            centre = history[-1] if history else self.x0
            std = self.init_spread * self.space.scale
            return self.space.sample_within_limits(
                lambda rows, g: centre + g.standard_normal((rows.shape[0], d)) * std, self.rng, n)
        P = self.particles
        # the paper predicts with its AR(3) model (seed 4.2); constant velocity without one
        shift = predicted_displacement(history, self.dynamics) if self.velocity else None
        cov = self.c_pred * weighted_covariance(P) + np.diag(self.sigma_pred ** 2)
        return gaussian_mutation(self.space, P if shift is None else P + shift, cov, self.rng)

    def _search(self, energy: CountingEnergy, history: list[np.ndarray]):
        X = self._initial_particles(history)
        X, pi, info = self._anneal(energy, X, self.M, self.schedule)
        self.particles = self._keep(X, pi, self.n)
        info["schedule"] = self.schedule
        return self._estimate(X, pi), info

    # ------------------------------------------------------------------ first-frame global search
    def global_init(self, energy, x0, spread=None, *, n: int = 1000, iterations: int = 40,
                    joints: str = "uniform", translation_dofs=(), translation_half_width=0.5,
                    yaw_dof: int | None = None, schedule: str = "ess") -> FrameResult:
        """Global ISA search from a wide initial distribution (algorithms.md 2.6); starts the track.

        Initial distribution around x0:
          * translation_dofs: uniform in x0 +- translation_half_width (scalar or per DOF, metres);
          * yaw_dof: uniform in x0[yaw] + [-pi, pi];
          * other DOFs: joints="uniform" draws uniformly within the limits (DOFs with an infinite
            limit fall back to the Gaussian below); joints="around" draws x0 + N(0, spread^2).
        spread: per-DOF standard deviation (array or scalar); default 10 * scale.
        The budget is n * iterations (+1 for the estimate), independent of the per-frame budget.
        The final particles seed the tracking particles (systematic resampling down to self.n).
        schedule: "ess" by default, because the energy spread of such a wide distribution is unknown
        and a fixed beta0 (tuned for tracking) collapses the set onto one particle when V differs by
        hundreds between particles; "polynomial" uses the tracking schedule.
        The yaw is a plain Euclidean DOF here: give it finite limits (or re-anchor it, 1.4) so that
        the weighted mean does not average particles 2 pi apart.
        """
        space, d = self.space, self.space.dim
        x0 = space.clamp(space.check_pose(x0, "initial pose x0"))
        if joints not in ("uniform", "around"):
            raise OptimizerInputError(f"joints must be 'uniform' or 'around', got {joints!r}")
        if n < 2 or iterations < 1:
            raise OptimizerInputError("global_init needs n >= 2 particles and iterations >= 1")
        spread = 10.0 * space.scale if spread is None else np.broadcast_to(np.asarray(spread, float), (d,)).copy()
        if np.any(spread < 0) or not np.all(np.isfinite(spread)):
            raise OptimizerInputError("spread must be finite and >= 0 per DOF")
        tdofs = np.asarray(translation_dofs, dtype=int).reshape(-1)
        special = np.zeros(d, dtype=bool)
        if tdofs.size:
            if tdofs.min() < 0 or tdofs.max() >= d:
                raise OptimizerInputError(f"translation_dofs must be DOF indices in [0, {d})")
            special[tdofs] = True
        if yaw_dof is not None:
            if not 0 <= yaw_dof < d:
                raise OptimizerInputError(f"yaw_dof must be a DOF index in [0, {d})")
            special[yaw_dof] = True
        half = np.broadcast_to(np.asarray(translation_half_width, float), (tdofs.size,))
        finite_box = np.isfinite(space.lower) & np.isfinite(space.upper)
        uniform_mask = ~special & finite_box if joints == "uniform" else np.zeros(d, dtype=bool)
        gauss_mask = ~special & ~uniform_mask

        def propose(rows, g):
            k = rows.shape[0]
            X = np.repeat(x0[None, :], k, axis=0)
            if tdofs.size:
                X[:, tdofs] = x0[tdofs] + g.uniform(-1.0, 1.0, (k, tdofs.size)) * half
            if yaw_dof is not None:
                X[:, yaw_dof] = x0[yaw_dof] + g.uniform(-math.pi, math.pi, k)
            if uniform_mask.any():
                X[:, uniform_mask] = g.uniform(space.lower[uniform_mask], space.upper[uniform_mask],
                                               (k, int(uniform_mask.sum())))
            if gauss_mask.any():
                X[:, gauss_mask] += g.standard_normal((k, int(gauss_mask.sum()))) * spread[gauss_mask]
            return X

        if schedule not in ("polynomial", "ess"):
            raise OptimizerInputError(f"global_init schedule must be 'polynomial' or 'ess', got {schedule!r}")
        counted = CountingEnergy(energy, d, limit=n * iterations + 1)
        X = space.sample_within_limits(propose, self.rng, n)
        X, pi, info = self._anneal(counted, X, iterations, schedule)
        info["schedule"] = schedule
        estimate = self._estimate(X, pi)
        searched = counted.count
        v = float(counted(estimate[None, :])[0])
        self.start(estimate)
        self.particles = self._keep(X, pi, self.n)
        info.update(seed=self.seed, search_evaluations=searched, energy_calls=counted.calls,
                    optimizer=self.name, stage="global_init")
        return FrameResult(estimate=estimate, energy=v, evaluations=counted.count, info=info)
