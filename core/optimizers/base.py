"""The shared optimiser interface: pose space, batched energy with evaluation counting, frame result.

Every optimiser minimises a black-box energy V evaluated on a *batch* of poses (P, D) -> (P,).
One call per particle set is what makes the particle methods fast, so the interface is batched.
The helpers here (weights, resampling, Gaussian mutation with a jittered Cholesky factor, limit
handling) are shared by ISA, APF, PF and FSA.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

EnergyFn = Callable[[np.ndarray], np.ndarray]   # (P, D) -> (P,), lower is better

TRANSLATION_SCALE_M = 0.02                      # algorithms.md 1.6: 20 mm
ANGLE_SCALE_RAD = math.radians(5.0)             # algorithms.md 1.6: 5 degrees
# Covariance floor of the mutations (algorithms.md 2.2): 1 mm for translations, 0.2 deg for angles,
# expressed as fractions of the per-DOF scale so that it follows a user-chosen scale.
FLOOR_FRACTION_TRANSLATION = 0.001 / 0.02
FLOOR_FRACTION_ANGLE = 0.2 / 5.0
DEFAULT_BUDGET = 3000                           # algorithms.md 0.3: V evaluations per frame


class OptimizerInputError(ValueError):
    """Bad arguments given to an optimiser (shapes, limits, parameters)."""


class EnergyOutputError(ValueError):
    """The energy function returned something that is not one finite-or-inf number per pose."""


class BudgetExceededError(RuntimeError):
    """An optimiser asked for more energy evaluations than its budget allows (a bug, not user input)."""


def _as_vector(name: str, value, size: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1:
        raise OptimizerInputError(f"{name} must be a 1-D array, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise OptimizerInputError(f"{name} has {arr.shape[0]} entries but the pose space has {size} DOF")
    return arr


@dataclass
class PoseSpace:
    """Box-limited pose space with a per-DOF scale (algorithms.md 1.5, 1.6).

    lower/upper may hold -inf/inf (free root). `translation` marks DOFs measured in metres; it only
    chooses the default covariance floor (1 mm vs 0.2 deg).
    """
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    names: list[str]
    translation: np.ndarray | None = None

    def __post_init__(self):
        self.lower = _as_vector("lower", self.lower)
        d = self.lower.shape[0]
        if d == 0:
            raise OptimizerInputError("the pose space has no DOF: give at least one lower/upper limit")
        self.upper = _as_vector("upper", self.upper, d)
        self.scale = _as_vector("scale", self.scale, d)
        self.names = [str(n) for n in self.names]
        if len(self.names) != d:
            raise OptimizerInputError(f"names has {len(self.names)} entries, limits have {d}: give one name per DOF")
        if np.isnan(self.lower).any() or np.isnan(self.upper).any():
            raise OptimizerInputError("joint limits contain NaN: use -inf/inf for a free DOF")
        bad = np.flatnonzero(self.lower > self.upper)
        if bad.size:
            raise OptimizerInputError(
                f"lower > upper for DOF {[self.names[i] for i in bad]}: swap or fix these joint limits")
        if not (np.all(np.isfinite(self.scale)) and np.all(self.scale > 0)):
            raise OptimizerInputError("scale must be finite and > 0 for every DOF (e.g. 0.02 m, 5 deg in rad)")
        if self.translation is None:
            self.translation = np.zeros(d, dtype=bool)
        self.translation = np.asarray(self.translation, dtype=bool)
        if self.translation.shape != (d,):
            raise OptimizerInputError(f"translation mask must have shape ({d},), got {self.translation.shape}")

    @classmethod
    def with_default_scale(cls, lower, upper, names, translation) -> "PoseSpace":
        """Scale 0.02 m for translation DOFs and 5 deg for angles (algorithms.md 1.6)."""
        translation = np.asarray(translation, dtype=bool)
        scale = np.where(translation, TRANSLATION_SCALE_M, ANGLE_SCALE_RAD)
        return cls(lower=lower, upper=upper, scale=scale, names=list(names), translation=translation)

    @property
    def dim(self) -> int:
        return self.lower.shape[0]

    def default_floor(self) -> np.ndarray:
        """Standard deviations of the covariance floor (1 mm / 0.2 deg at the default scale)."""
        frac = np.where(self.translation, FLOOR_FRACTION_TRANSLATION, FLOOR_FRACTION_ANGLE)
        return frac * self.scale

    def check_pose(self, x, what: str = "pose") -> np.ndarray:
        x = _as_vector(what, x, self.dim)
        if not np.all(np.isfinite(x)):
            raise OptimizerInputError(f"{what} contains NaN or inf at DOF "
                                      f"{[self.names[i] for i in np.flatnonzero(~np.isfinite(x))]}")
        return x

    def clamp(self, X: np.ndarray) -> np.ndarray:
        return np.clip(X, self.lower, self.upper)

    def violations(self, X: np.ndarray) -> np.ndarray:
        """Boolean per row: True if any DOF is outside its limits."""
        return np.any((X < self.lower) | (X > self.upper), axis=-1)

    def sample_within_limits(self, X_proposed_fn: Callable[[np.ndarray, np.random.Generator], np.ndarray],
                             rng: np.random.Generator, n: int, redraws: int = 10) -> np.ndarray:
        """Draw n poses; rows that violate a limit are redrawn up to `redraws` times, then clamped (1.5).

        X_proposed_fn(rows, rng) returns fresh proposals (len(rows), D) for the given row indices, so
        a proposal can depend on the row (its parent particle). Redrawing whole rows keeps the accepted
        samples distributed as the proposal truncated to the box.
        """
        rows = np.arange(n)
        X = np.asarray(X_proposed_fn(rows, rng), dtype=float)
        if X.shape != (n, self.dim):
            raise OptimizerInputError(f"proposal returned shape {X.shape}, expected {(n, self.dim)}")
        bad = rows[self.violations(X)]
        for _ in range(redraws):
            if bad.size == 0:
                break
            X[bad] = X_proposed_fn(bad, rng)
            bad = bad[self.violations(X[bad])]
        if bad.size:
            X[bad] = self.clamp(X[bad])
        return X


class CountingEnergy:
    """Wraps an EnergyFn: validates each batch and counts single-pose evaluations (P per call).

    NaN energies become +inf (a pose the renderer cannot score is simply a bad pose). `limit` makes
    an optimiser that overspends fail loudly instead of silently breaking the equal-budget comparison.
    """

    def __init__(self, energy: EnergyFn, dim: int, limit: int | None = None):
        if not callable(energy):
            raise OptimizerInputError("energy must be a callable mapping a (P, D) array of poses to (P,) energies")
        self.energy = energy
        self.dim = dim
        self.limit = limit
        self.count = 0
        self.calls = 0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.ascontiguousarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise OptimizerInputError(f"energy batch must have shape (P, {self.dim}), got {X.shape}")
        p = X.shape[0]
        if self.limit is not None and self.count + p > self.limit:
            raise BudgetExceededError(f"{self.count + p} evaluations requested, budget is {self.limit}")
        V = np.asarray(self.energy(X), dtype=float)
        if V.shape == (p, 1):
            V = V[:, 0]
        if V.shape != (p,):
            raise EnergyOutputError(f"energy returned shape {V.shape} for {p} poses: it must return one value "
                                    f"per pose, shape ({p},)")
        if np.isneginf(V).any():
            raise EnergyOutputError("energy returned -inf: energies must be bounded below (use +inf for invalid poses)")
        V = np.where(np.isnan(V), np.inf, V)
        self.count += p
        self.calls += 1
        return V


@dataclass
class FrameResult:
    estimate: np.ndarray          # (D,)
    energy: float                 # V(estimate), evaluated once more and counted
    evaluations: int              # single-pose evaluations this frame, including the one above
    info: dict = field(default_factory=dict)


# ---------------------------------------------------------------- shared numerical helpers

def boltzmann_weights(V: np.ndarray, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """g = exp(-beta (V - Vmin)) (max g = 1, no underflow of the best) and normalised pi."""
    finite = np.isfinite(V)
    if not finite.any():
        raise EnergyOutputError("every pose in the batch has infinite/NaN energy: check the energy function "
                                "and that the initial pose is inside the images")
    vmin = V[finite].min()
    g = np.zeros_like(V)
    g[finite] = np.exp(-beta * (V[finite] - vmin))
    return g, g / g.sum()


def systematic_resample(pi: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """n indices with one uniform offset (low-variance resampling)."""
    positions = (rng.random() + np.arange(n)) / n
    cdf = np.cumsum(pi)
    cdf[-1] = 1.0
    return np.minimum(np.searchsorted(cdf, positions, side="right"), len(pi) - 1)


def multinomial_resample(pi: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    cdf = np.cumsum(pi)
    cdf[-1] = 1.0
    return np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(pi) - 1)


RESAMPLERS = {"systematic": systematic_resample, "multinomial": multinomial_resample}


def weighted_covariance(X: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Covariance of the rows of X; unbiased (n-1) for equal weights, reliability-weighted otherwise."""
    n = X.shape[0]
    if w is None:
        if n < 2:
            return np.zeros((X.shape[1], X.shape[1]))
        Xc = X - X.mean(axis=0)
        return Xc.T @ Xc / (n - 1)
    mu = w @ X
    Xc = X - mu
    denom = 1.0 - float(w @ w)
    if denom <= 1e-12:             # all weight on one particle: no spread information
        return np.zeros((X.shape[1], X.shape[1]))
    return (Xc * w[:, None]).T @ Xc / denom


def cholesky_jitter(S: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of S; adds growing diagonal jitter if S is numerically not positive definite."""
    S = 0.5 * (S + S.T)
    try:
        return np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        pass
    jitter = 1e-12 * max(float(np.mean(np.abs(np.diag(S)))), 1e-300)
    eye = np.eye(S.shape[0])
    for _ in range(40):
        try:
            return np.linalg.cholesky(S + jitter * eye)
        except np.linalg.LinAlgError:
            jitter *= 10.0
    # Last resort: the diagonal alone is always a valid covariance.
    return np.diag(np.sqrt(np.maximum(np.diag(S), 0.0)))


def gaussian_mutation(space: PoseSpace, centres: np.ndarray, cov: np.ndarray,
                      rng: np.random.Generator, redraws: int = 10) -> np.ndarray:
    """centres[i] + N(0, cov) per row, with the redraw-then-clamp limit rule (1.5)."""
    L = cholesky_jitter(cov)
    d = centres.shape[1]

    def propose(rows, g):
        return centres[rows] + g.standard_normal((rows.shape[0], d)) @ L.T

    return space.sample_within_limits(propose, rng, centres.shape[0], redraws)


def particle_sets(optimizer, n: int, M: int | None, budget: int | None, what: str, step: str) -> tuple[int, int]:
    """(particles, sets) for ISA/APF: M sets of n particles within the budget (M = budget // n when not
    given; an explicit M sets the budget to n * M). `step` names one set ("iteration", "layer")."""
    if n < 2:
        raise OptimizerInputError(f"{what} needs at least 2 particles, got n={n}")
    n = int(n)
    if M is None:
        M = split_budget(optimizer.budget, n, what)
    else:
        if budget is not None and int(M) * n > optimizer.budget:
            raise OptimizerInputError(f"{what}: n*M = {n * M} exceeds the budget {budget}: lower M or n")
        M = int(M)
        optimizer.budget = n * M
    if M < 1:
        raise OptimizerInputError(f"{what} needs at least one {step} (M >= 1)")
    return n, M


def split_budget(budget: int, n: int, what: str) -> int:
    """Iterations for n particles within the budget (floor); at least one."""
    if budget < n:
        raise OptimizerInputError(f"{what}: budget {budget} is smaller than one particle set of {n}: "
                                  f"raise the budget or lower the particle count")
    return budget // n


# ---------------------------------------------------------------- the interface

class Optimizer(ABC):
    """Tracks one pose per frame; keeps its own particles/state between frames.

    Subclasses implement `_search(energy, history) -> (estimate, info)` where `energy` is a
    CountingEnergy limited to `self.search_budget` evaluations. The base class evaluates the
    estimate once more (counted) and fills the FrameResult.
    """
    name: str = "base"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, **params):
        if not isinstance(space, PoseSpace):
            raise OptimizerInputError("space must be a PoseSpace (limits, per-DOF scale, names)")
        if budget is not None and (int(budget) != budget or budget < 1):
            raise OptimizerInputError(f"budget must be a positive integer number of evaluations, got {budget!r}")
        if params:
            raise OptimizerInputError(f"unknown parameter(s) for {self.name}: {sorted(params)}")
        self.space = space
        self.budget = DEFAULT_BUDGET if budget is None else int(budget)
        self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)
        self.x0: np.ndarray | None = None
        self.frame_index = 0

    @property
    def search_budget(self) -> int:
        """Evaluations the search itself may use (the final re-evaluation of the estimate is extra)."""
        return self.budget

    def start(self, x0: np.ndarray) -> None:
        """Common initial pose (first-frame estimate); forgets any particles of an earlier track."""
        self.x0 = self.space.clamp(self.space.check_pose(x0, "initial pose x0"))
        self.frame_index = 0
        self._reset()

    def _reset(self) -> None:
        """Drop per-track state (particles, histories)."""

    # ---- what it carries from frame to frame, as plain data (a checkpoint stores it; restore takes it back)
    pose_arrays: tuple[str, ...] = ("x0",)  # the names in state_arrays() that hold poses

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The arrays this optimiser carries between frames, by name: the frame count, the start pose and
        the subclass's own (_carried_arrays). The random generator's state is random_state()."""
        arrays = {"frame_index": np.array(self.frame_index, dtype=np.int64)}
        if self.x0 is not None:
            arrays["x0"] = self.x0
        arrays.update(self._carried_arrays())
        return arrays

    def random_state(self) -> dict:
        """The random generator's state: numpy's bit_generator.state, plain (JSON-able) data."""
        return self.rng.bit_generator.state

    def restore(self, arrays: dict, random_state: dict | None = None) -> None:
        """Take back what state_arrays() (and random_state()) gave, on an optimiser built with the same settings."""
        arrays = dict(arrays)
        self.frame_index = int(arrays.pop("frame_index", 0))
        x0 = arrays.pop("x0", None)
        self.x0 = None if x0 is None else np.asarray(x0, dtype=float)
        self._restore_carried(arrays)
        if random_state is not None:
            self.rng.bit_generator.state = random_state

    def map_poses(self, convert: Callable[[np.ndarray], np.ndarray], start: bool = True) -> None:
        """Apply `convert` to every pose array carried between frames (the start pose x0 too unless not `start`)."""
        arrays = self.state_arrays()
        names = [n for n in self.pose_arrays if n in arrays and (start or n != "x0")]
        self.restore({**arrays, **{n: convert(arrays[n]) for n in names}})

    def _carried_arrays(self) -> dict[str, np.ndarray]:
        """The subclass's arrays carried between frames (particles, weights...); none by default."""
        return {}

    def _restore_carried(self, arrays: dict) -> None:
        """Take back _carried_arrays()' arrays (an absent name: nothing carried yet)."""

    def _check_history(self, history: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [self.space.check_pose(h, f"history[{i}]") for i, h in enumerate(history)]

    def track_frame(self, energy: EnergyFn, history: Sequence[np.ndarray] = ()) -> FrameResult:
        if self.x0 is None:
            raise OptimizerInputError(f"{self.name}: call start(x0) with the initial pose before track_frame")
        history = self._check_history(history)
        counted = CountingEnergy(energy, self.space.dim, limit=self.search_budget + 1)
        estimate, info = self._search(counted, history)
        searched = counted.count
        v = float(counted(estimate[None, :])[0])
        info.update(seed=self.seed, frame=self.frame_index, search_evaluations=searched,
                    energy_calls=counted.calls, optimizer=self.name)
        self.frame_index += 1
        return FrameResult(estimate=estimate, energy=v, evaluations=counted.count, info=info)

    @abstractmethod
    def _search(self, energy: CountingEnergy, history: list[np.ndarray]) -> tuple[np.ndarray, dict]:
        """Search for the frame's pose; return (estimate (D,), info dict)."""
