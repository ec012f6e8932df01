"""A plausibility gate on the root: between two solved frames the root (the hips) cannot move faster than a person
can. A solution that needs a faster move has jumped onto something else (another person who passes close, a
shadow) and is rejected; the frame is searched again around the prediction, with the root held within the reach
of the last frame's. The bound and the figures behind it: docs/measurements.md, "Other people in the room".

The gate only refuses single jumps: a model that drifts onto another person no faster than a person walks passes
it. Where it never trips, the tracker's results are exactly those without it (it draws no random numbers then).
"""
import numpy as np

from ..optimizers.isa import InteractingSimulatedAnnealing

# A sprinter's hips peak near 12 m/s, but only after 30-40 m of run-up, more than any capture volume holds; the
# body's centre in dance, jumps or a fall rarely exceeds 5-6 m/s. 10 m/s leaves a margin over all of these.
MAX_ROOT_SPEED = 10.0  # m/s
# The estimate's own frame-to-frame scatter, which a high frame rate would otherwise read as speed.
ROOT_JITTER = 0.05  # metres per solved frame
# The first frame's estimate may still be as far off as the subject's placement may be (the architecture's 20 cm),
# and the first tracked frame corrects it: that step alone may be this much longer.
FIRST_STEP_SLACK = 0.2  # metres
# The re-search: the paper's per-frame budget, around the prediction.
SEARCH_PARTICLES = 200
SEARCH_ITERATIONS = 15
SEARCH_SPREAD_SCALES = 1  # the joints' spread around the prediction, in per-DOF scales
SEARCH_TILT = float(np.deg2rad(8.0))  # the root's spread about the horizontal axes
SEARCH_YAW = float(np.deg2rad(20.0))
# Each re-search its own seed, from the run's seed and the frame: a resumed run searches as an unbroken one.
FRAME_SEED_STRIDE = 7907


def root_step_limit(frames_apart, fps, speed=MAX_ROOT_SPEED, jitter=ROOT_JITTER):
    """How far (metres) the root may move between two solved frames `frames_apart` apart at `fps`."""
    if not fps or fps <= 0:
        raise ValueError(f"the gate needs the capture's frame rate, got {fps!r}")
    return speed * max(abs(int(frames_apart)), 1) / float(fps) + jitter


def hold_root(poses, centre, radius, translation_dofs):
    """`poses` (..., D) with the root translation moved onto the ball of `radius` around `centre` where it lies
    outside it (a copy)."""
    poses = np.array(poses, dtype=np.float64, copy=True)
    offset = poses[..., translation_dofs] - centre
    distance = np.linalg.norm(offset, axis=-1, keepdims=True)
    shrink = np.minimum(1.0, radius / np.maximum(distance, 1e-12))
    poses[..., translation_dofs] = centre + offset * shrink
    return poses


class RootGate:
    """The gate of one track. `space`: the optimisers' PoseSpace; `polish`: the local fit of a relative pose on the
    current frame (or None); `follow(step)`: moves the optimiser's particles by the step a re-searched estimate
    took (or None)."""

    def __init__(self, space, translation_dofs, rotation_dofs, fps, seed=0, polish=None, follow=None,
                 speed=MAX_ROOT_SPEED, jitter=ROOT_JITTER, particles=SEARCH_PARTICLES, iterations=SEARCH_ITERATIONS):
        self.space = space
        self.translation_dofs = np.asarray(translation_dofs, dtype=int)
        self.rotation_dofs = np.asarray(rotation_dofs, dtype=int)
        self.fps, self.seed = float(fps), int(seed)
        self.polish, self.follow = polish, follow
        self.speed, self.jitter = float(speed), float(jitter)
        self.particles, self.iterations = int(particles), int(iterations)
        root_step_limit(1, self.fps, self.speed, self.jitter)  # a bad frame rate fails here, not mid-take
        self.last_frame = None  # the frame solved last (carried in the checkpoint)
        self.first_step = False  # the next frame is the first after the initial one
        self.gated = []  # {"frame", "speed_m_per_s", "kept_speed_m_per_s", "limit_m_per_s"} per refused solution

    def limit(self, frame):
        """How far the root may have moved since the frame solved last."""
        apart = 1 if self.last_frame is None else int(frame) - self.last_frame
        slack = FIRST_STEP_SLACK if self.first_step else 0.0
        return root_step_limit(apart, self.fps, self.speed, self.jitter) + slack, max(abs(apart), 1)

    def start(self, frame):
        """The first frame is solved: later ones are measured from it."""
        self.last_frame = int(frame)
        self.first_step = True

    def state(self):
        """What a checkpoint keeps (plain data)."""
        return {"last_frame": self.last_frame, "first_step": self.first_step}

    def restore(self, state):
        """Continue from state() (None: from a checkpoint written before the gate; the next frame is not gated)."""
        state = state or {}
        last = state.get("last_frame")
        self.last_frame = None if last is None else int(last)
        self.first_step = bool(state.get("first_step", False))

    def check(self, estimate, energy, evaluations, frame, history, energy_fn):
        """`estimate` (relative) of `frame`, after its search, local fit and limb recovery; `history`: the relative
        poses of the frames solved before it (most recent last). Returns (estimate, energy, evaluations): unchanged
        when the root moved no faster than the bound, else the re-search's."""
        if self.last_frame is None or not history:
            self.start(frame)
            return estimate, energy, evaluations
        limit, apart = self.limit(frame)
        previous = np.asarray(history[-1], dtype=np.float64)
        centre = previous[self.translation_dofs]
        step = float(np.linalg.norm(np.asarray(estimate)[self.translation_dofs] - centre))
        self.last_frame, self.first_step = int(frame), False
        if step <= limit:
            return estimate, energy, evaluations
        found, found_energy, used = self.research(energy_fn, history, centre, limit, frame)
        kept_step = float(np.linalg.norm(found[self.translation_dofs] - centre))
        to_speed = self.fps / apart
        self.gated.append({"frame": int(frame), "speed_m_per_s": round(step * to_speed, 3),
                           "kept_speed_m_per_s": round(kept_step * to_speed, 3),
                           "limit_m_per_s": round(limit * to_speed, 3)})
        if self.follow is not None:
            self.follow(found - np.asarray(estimate, dtype=np.float64))
        return found, found_energy, evaluations + used

    def research(self, energy_fn, history, centre, limit, frame):
        """The frame searched again around the constant-velocity prediction from `history`, every root beyond
        `limit` of `centre` (the last frame's root) scored and kept on the bound. Returns (estimate, energy,
        evaluations)."""
        last = np.asarray(history[-1], dtype=np.float64)
        predicted = 2.0 * last - np.asarray(history[-2], dtype=np.float64) if len(history) >= 2 else last
        predicted = hold_root(self.space.clamp(predicted[None])[0], centre, limit, self.translation_dofs)

        def held_energy(poses):
            return energy_fn(hold_root(poses, centre, limit, self.translation_dofs))

        spread = self.space.scale * SEARCH_SPREAD_SCALES
        spread[self.rotation_dofs[:2]] = SEARCH_TILT
        spread[self.rotation_dofs[2]] = SEARCH_YAW
        searcher = InteractingSimulatedAnnealing(self.space, seed=self.seed + FRAME_SEED_STRIDE * int(frame),
                                                 n=self.particles, schedule="ess")
        result = searcher.global_init(held_energy, predicted, spread, n=self.particles, iterations=self.iterations,
                                      joints="around", translation_dofs=self.translation_dofs,
                                      translation_half_width=limit, yaw_dof=None)
        # the prediction itself stays a candidate: a search in all DOFs may end above it
        candidates = np.stack([hold_root(result.estimate, centre, limit, self.translation_dofs), predicted])
        energies = np.asarray(energy_fn(candidates), dtype=np.float64)
        best = int(np.argmin(energies))
        found, found_energy = candidates[best], float(energies[best])
        evaluations = result.evaluations + 2
        if self.polish is not None:
            polished = hold_root(self.polish(found), centre, limit, self.translation_dofs)
            polished_energy = float(energy_fn(polished[None])[0])
            evaluations += 1
            if polished_energy < found_energy:
                found, found_energy = polished, polished_energy
        return found, found_energy, evaluations
