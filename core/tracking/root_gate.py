"""A plausibility gate on the root: between two solved frames the root (the hips) cannot move faster than a person
can, nor change its velocity faster than a body can. A solution that needs either has jumped onto something else
(another person who passes close, a shadow) and is rejected; the frame is searched again around the prediction,
with the root held within the reach of the last frame's (speed) or of the constant-velocity prediction (change of
velocity). The bounds and the figures behind them: docs/measurements.md, "Other people in the room".

The speed bound alone refuses single jumps but not a model that steps onto another person at 7-10 m/s frame after
frame; the bound on the change of velocity refuses that too. Where it never trips, the tracker's results are
exactly those without it (it draws no random numbers then).
"""
import numpy as np

from ..optimizers.isa import InteractingSimulatedAnnealing

# A sprinter's hips peak near 12 m/s, but only after 30-40 m of run-up, more than any capture volume holds; the
# body's centre in dance, jumps or a fall rarely exceeds 5-6 m/s. 10 m/s leaves a margin over all of these.
MAX_ROOT_SPEED = 10.0  # m/s
# The estimate's own frame-to-frame scatter, which a high frame rate would otherwise read as speed.
ROOT_JITTER = 0.05  # metres per solved frame
# The hips' acceleration: a jump's take-off or landing and a stumble stay near 2-3 g; 5 g leaves a margin. Over a
# frame at 30 fps that is 5.6 cm from where the last velocity carries the hips (the truth of every sample scene,
# dance's kick and jump included, strays at most 3.1 cm); the scatter of the estimate comes on top.
MAX_ROOT_ACCELERATION = 50.0  # m/s^2
# The estimate's own swerve: a frame that recovers from a bad one moves its root back by the error it had, 0.11 m
# after a frame 93 mm off on a three-camera crossing, which a gate must not refuse (docs/measurements.md).
SWERVE_SCATTER = 0.1  # metres
# A swerve back towards where the root went this long ago, carried on at its pace then, is the model coming back to
# its person after losing it, not leaving: it passes (docs/measurements.md).
LONG_TRACK_SECONDS = 1.0 / 3.0
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


def root_swerve_limit(frames_apart, frames_apart_before, fps, acceleration=MAX_ROOT_ACCELERATION,
                      jitter=SWERVE_SCATTER):
    """How far (metres) the root may land from the constant-velocity prediction, the velocity taken over the last
    `frames_apart_before` frames and carried `frames_apart` frames on: a constant acceleration puts it
    acceleration x t x (t + t_before) / 2 away."""
    if not fps or fps <= 0:
        raise ValueError(f"the gate needs the capture's frame rate, got {fps!r}")
    t, t_before = max(abs(int(frames_apart)), 1) / float(fps), max(abs(int(frames_apart_before)), 1) / float(fps)
    return acceleration * t * (t + t_before) / 2.0 + jitter


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
    took (or None); `set_aside(refused, predicted)`: leaves out of the frame's energy the evidence that pulled the
    refused estimate away and returns what it left out (a list of camera names; or None)."""

    def __init__(self, space, translation_dofs, rotation_dofs, fps, seed=0, polish=None, follow=None, set_aside=None,
                 speed=MAX_ROOT_SPEED, jitter=ROOT_JITTER, acceleration=MAX_ROOT_ACCELERATION, scatter=SWERVE_SCATTER,
                 particles=SEARCH_PARTICLES, iterations=SEARCH_ITERATIONS):
        self.space = space
        self.translation_dofs = np.asarray(translation_dofs, dtype=int)
        self.rotation_dofs = np.asarray(rotation_dofs, dtype=int)
        self.fps, self.seed = float(fps), int(seed)
        self.polish, self.follow, self.set_aside = polish, follow, set_aside
        self.speed, self.jitter = float(speed), float(jitter)
        self.acceleration, self.scatter = float(acceleration), float(scatter)
        self.particles, self.iterations = int(particles), int(iterations)
        root_step_limit(1, self.fps, self.speed, self.jitter)  # a bad frame rate fails here, not mid-take
        self.last_frame = None  # the frame solved last (carried in the checkpoint)
        self.first_step = False  # the next frame is the first after the initial one
        # The roots (absolute translations) of the last LONG_TRACK_SECONDS, (frame, root) each, the frame solved
        # last at the end: kept here rather than read from the tracker's history, which a turned-round body resets
        # to its new pose. The velocity to predict from (per frame, and over how many frames it was measured), None
        # after the initial frame, whose placement the first step corrects.
        self.track, self.velocity = [], None
        self.track_frames = int(round(LONG_TRACK_SECONDS * self.fps))
        # per refused solution: {"frame", "speed_m_per_s", "kept_speed_m_per_s", "limit_m_per_s"} (too fast) or
        # {"frame", "off_prediction_m", "kept_off_prediction_m", "limit_m"} (swerved from its prediction)
        self.gated = []

    def limit(self, frame):
        """How far the root may have moved since the frame solved last."""
        apart = 1 if self.last_frame is None else int(frame) - self.last_frame
        slack = FIRST_STEP_SLACK if self.first_step else 0.0
        return root_step_limit(apart, self.fps, self.speed, self.jitter) + slack, max(abs(apart), 1)

    def start(self, frame, root=None):
        """The first frame is solved (its root translation `root`): later ones are measured from it."""
        self.last_frame = int(frame)
        self.first_step = True
        self.velocity = None
        self.track = [] if root is None else [(int(frame), np.asarray(root, dtype=np.float64).copy())]

    @property
    def last_root(self):
        """The root of the frame solved last, or None when it is not known (a checkpoint from before it was kept)."""
        return self.track[-1][1] if self.track else None

    def state(self):
        """What a checkpoint keeps (plain data)."""
        return {"last_frame": self.last_frame, "first_step": self.first_step,
                "velocity": None if self.velocity is None else [self.velocity[0].tolist(), self.velocity[1]],
                "track": [[f, r.tolist()] for f, r in self.track]}

    def restore(self, state):
        """Continue from state() (None: from a checkpoint written before the gate; the next frame is not gated).
        A checkpoint from before the bound on the change of velocity holds the next frame to the speed bound only."""
        state = state or {}
        last, velocity = state.get("last_frame"), state.get("velocity")
        self.last_frame = None if last is None else int(last)
        self.first_step = bool(state.get("first_step", False))
        self.velocity = None if velocity is None else (np.asarray(velocity[0], dtype=np.float64), int(velocity[1]))
        self.track = [(int(f), np.asarray(r, dtype=np.float64)) for f, r in state.get("track", [])]

    def prediction(self, frame):
        """Where the root's velocity carries it at `frame`, and how far from there it may land: (root (3,), limit)
        or None without a velocity to predict from."""
        if self.velocity is None or self.last_root is None:
            return None
        apart = max(abs(int(frame) - self.last_frame), 1)
        limit = root_swerve_limit(apart, self.velocity[1], self.fps, self.acceleration, self.scatter)
        return self.last_root + self.velocity[0] * apart, limit

    def long_prediction(self, frame):
        """Where the root's pace of LONG_TRACK_SECONDS ago carries it at `frame` (None while the track is shorter)."""
        if len(self.track) < 3 or self.track[-1][0] - self.track[0][0] < self.track_frames:
            return None
        (f_old, r_old), (f_mid, r_mid) = self.track[0], self.track[len(self.track) // 2]
        return r_old + (r_mid - r_old) * (int(frame) - f_old) / max(f_mid - f_old, 1)

    def swerves(self, root, frame):
        """(prediction, limit) when `root` at `frame` swerved from its prediction beyond the limit and not back
        towards the long track; else None."""
        swerve = self.prediction(frame)
        if swerve is None or np.linalg.norm(root - swerve[0]) <= swerve[1]:
            return None
        along = self.long_prediction(frame)
        if along is not None and np.linalg.norm(root - along) < np.linalg.norm(swerve[0] - along):
            return None
        return swerve

    def check(self, estimate, energy, evaluations, frame, history, energy_fn):
        """`estimate` (relative) of `frame`, after its search, local fit, turn and limb recovery; `history`: the
        relative poses of the frames solved before it (most recent last). Returns (estimate, energy, evaluations):
        unchanged when the root moved no faster than the speed bound and landed within the swerve bound of its
        prediction, else the re-search's."""
        if self.last_frame is None or not history:
            self.start(frame, np.asarray(estimate)[self.translation_dofs])
            return estimate, energy, evaluations
        limit, apart = self.limit(frame)
        last_root = self.last_root if self.last_root is not None else \
            np.asarray(history[-1], dtype=np.float64)[self.translation_dofs]
        root = np.asarray(estimate, dtype=np.float64)[self.translation_dofs]
        step = float(np.linalg.norm(root - last_root))
        swerve = self.swerves(root, frame) if step <= limit else None
        found = None
        if step > limit:
            centre, bound, predicted_root = last_root, limit, None
        elif swerve is not None:
            centre, bound = swerve
            predicted_root = centre
        else:
            centre = None
        if centre is not None:
            predicted = self.predicted_pose(history, centre, bound, predicted_root)
            left_out = [] if self.set_aside is None else list(self.set_aside(estimate, predicted) or [])
            found, found_energy, used = self.research(energy_fn, predicted, centre, bound, frame)
            kept = float(np.linalg.norm(found[self.translation_dofs] - centre))
            if predicted_root is None:
                to_speed = self.fps / apart
                entry = {"speed_m_per_s": round(step * to_speed, 3), "kept_speed_m_per_s": round(kept * to_speed, 3),
                         "limit_m_per_s": round(bound * to_speed, 3)}
            else:
                entry = {"off_prediction_m": round(float(np.linalg.norm(root - centre)), 4),
                         "kept_off_prediction_m": round(kept, 4), "limit_m": round(float(bound), 4)}
            self.gated.append({"frame": int(frame), **entry, **({"views_left_out": left_out} if left_out else {})})
        if found is None:  # a refused frame's kept root is on a bound: no pace to predict from, the last one stays
            self.velocity = None if self.first_step else ((root - last_root) / apart, apart)
        kept_root = root if found is None else found[self.translation_dofs].copy()
        self.last_frame, self.first_step = int(frame), False
        self.track = [(f, r) for f, r in self.track if f >= int(frame) - self.track_frames] + [(int(frame), kept_root)]
        if found is None:
            return estimate, energy, evaluations
        if self.follow is not None:
            self.follow(found - np.asarray(estimate, dtype=np.float64))
        return found, found_energy, evaluations + used

    def predicted_pose(self, history, centre, limit, predicted_root=None):
        """The constant-velocity prediction from `history` (its root moved to `predicted_root` when given), within
        limits and its root within `limit` of `centre`."""
        last = np.asarray(history[-1], dtype=np.float64)
        predicted = 2.0 * last - np.asarray(history[-2], dtype=np.float64) if len(history) >= 2 else last.copy()
        if predicted_root is not None:
            predicted[self.translation_dofs] = predicted_root
        return hold_root(self.space.clamp(predicted[None])[0], centre, limit, self.translation_dofs)

    def research(self, energy_fn, predicted, centre, limit, frame):
        """The frame searched again around `predicted`, every root beyond `limit` of `centre` scored and kept on the
        bound. Returns (estimate, energy, evaluations)."""

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
