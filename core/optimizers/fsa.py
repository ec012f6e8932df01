"""Fast Simulated Annealing (Szu-Hartley), the global single-hypothesis optimiser (algorithms.md 5).

One chain per frame: Cauchy visits x + g_k sigma tan(pi(u - 1/2)) with g_k = g0/(1+k), Metropolis
acceptance at T_k = T0/(1+k), best-so-far output. FSA is sequential: each visit depends on the
previous acceptance, so the energy is called with one pose per iteration; only the T0 probe
(50 visits from the start pose) is one batch.
"""
from __future__ import annotations

import math

import numpy as np

from .base import CountingEnergy, Optimizer, OptimizerInputError, PoseSpace
from .dynamics import ConditionalGaussianDynamics


class FastSimulatedAnnealing(Optimizer):
    """FSA (algorithms.md 5.2-5.3). Defaults: budget 3000 evaluations = 1 start + 50 T0 probes + 2949
    iterations; sigma = s, g0 = 1, T0 = 0.1 median|dV| of the probes (or a fixed T0).

    groups: list of DOF index lists; when given, each move perturbs one uniformly chosen group
    ("block moves"). dynamics: optional model whose mean predicts the start pose from the previous
    estimates; otherwise constant velocity 2 x_{t-1} - x_{t-2} (4.5), or x_{t-1} with one estimate.
    """
    name = "fsa"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, *, g0: float = 1.0,
                 T0: float | None = None, t0_factor: float = 0.1, t0_visits: int = 50, sigma=None,
                 groups=None, dynamics: ConditionalGaussianDynamics | None = None,
                 predict: str = "constant_velocity", **params):
        super().__init__(space, budget, seed, **params)
        d = space.dim
        if g0 <= 0 or t0_factor <= 0:
            raise OptimizerInputError("FSA needs g0 > 0 and t0_factor > 0")
        if T0 is not None and not T0 > 0:
            raise OptimizerInputError(f"FSA T0 must be > 0 (or None for the automatic rule), got {T0}")
        if predict not in ("constant_velocity", "last"):
            raise OptimizerInputError(f"FSA predict must be 'constant_velocity' or 'last', got {predict!r}")
        self.g0, self.T0_fixed, self.t0_factor = float(g0), T0, float(t0_factor)
        self.t0_visits = 0 if T0 is not None else int(t0_visits)
        if T0 is None and self.t0_visits < 1:
            raise OptimizerInputError("the automatic T0 rule needs t0_visits >= 1 (or give T0)")
        self.iterations = self.budget - 1 - self.t0_visits
        if self.iterations < 1:
            raise OptimizerInputError(f"FSA budget {self.budget} leaves no iterations after the start evaluation "
                                      f"and {self.t0_visits} T0 probes: raise the budget")
        self.sigma = space.scale.copy() if sigma is None else np.broadcast_to(np.asarray(sigma, float), (d,)).copy()
        if np.any(self.sigma <= 0):
            raise OptimizerInputError("FSA sigma must be > 0 per DOF")
        self.groups = None
        if groups is not None:
            self.groups = [np.asarray(g, dtype=int).reshape(-1) for g in groups]
            if not self.groups or any(g.size == 0 or g.min() < 0 or g.max() >= d for g in self.groups):
                raise OptimizerInputError(f"groups must be non-empty lists of DOF indices in [0, {d})")
        if dynamics is not None and not isinstance(dynamics, ConditionalGaussianDynamics):
            raise OptimizerInputError("dynamics must be a ConditionalGaussianDynamics or None")
        self.dynamics, self.predict = dynamics, predict

    def _start_pose(self, history):
        if not history:
            return self.x0
        if self.dynamics is not None:
            return self.space.clamp(self.dynamics.predict_from_history(history))
        if self.predict == "constant_velocity" and len(history) >= 2:
            return self.space.clamp(2.0 * history[-1] - history[-2])
        return history[-1]

    def _visit(self, x: np.ndarray, g: float, k: int) -> np.ndarray:
        """k Cauchy visits around x (all DOFs, or one random group per visit), redraw-then-clamp limits."""
        d = self.space.dim

        def propose(rows, rng):
            m = rows.shape[0]
            # u in the open interval (0, 1): tan stays finite.
            u = np.clip(rng.random((m, d)), 1e-12, 1.0 - 1e-12)
            step = g * self.sigma * np.tan(math.pi * (u - 0.5))
            if self.groups is not None:
                mask = np.zeros((m, d), dtype=bool)
                for r, gi in enumerate(rng.integers(len(self.groups), size=m)):
                    mask[r, self.groups[gi]] = True
                step = np.where(mask, step, 0.0)
            return x + step

        return self.space.sample_within_limits(propose, self.rng, k)

    def _search(self, energy: CountingEnergy, history):
        x = np.array(self._start_pose(history), dtype=float)
        vx = float(energy(x[None])[0])
        best_x, best_v = x.copy(), vx
        if self.T0_fixed is not None:
            T0 = float(self.T0_fixed)
        else:
            Y = self._visit(x, self.g0, self.t0_visits)
            VY = energy(Y)
            dv = np.abs(VY - vx)
            dv = dv[np.isfinite(dv) & (dv > 0)]
            # Greedy fallback when no probe changed the energy measurably.
            T0 = self.t0_factor * float(np.median(dv)) if dv.size else 1e-12 * max(1.0, abs(vx))
            j = int(np.argmin(VY))
            if VY[j] < best_v:                   # the probes are evaluations too: keep the best
                best_x, best_v = Y[j].copy(), float(VY[j])
        accepted = 0
        for k in range(self.iterations):
            g = self.g0 / (1.0 + k)
            T = T0 / (1.0 + k)
            y = self._visit(x, g, 1)
            vy = float(energy(y)[0])
            if vy <= vx or self.rng.random() < math.exp(-(vy - vx) / T):
                x, vx = y[0], vy
                accepted += 1
                if vx < best_v:
                    best_x, best_v = x.copy(), vx
        info = {"T0": T0, "iterations": self.iterations, "acceptance_rate": accepted / self.iterations,
                "best_energy": best_v, "block_moves": self.groups is not None}
        return best_x, info
