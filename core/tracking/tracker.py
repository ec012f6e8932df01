"""The per-frame tracking loop: initialise, predict, optimise, refine, turn round, recover limbs, adapt colour,
checkpoint.

The same loop serves the command line, the Blender modal operator and the tests. It never touches Blender: it
reads a Capture, scores poses with an EnergyModel and hands each frame's estimate to a callback as soon as it is
solved, so nothing solved is ever lost. Tracker coordinates the parts, each in its own module: observing a frame
(observation.py), the root anchor the optimisers' poses are relative to (anchor.py), the first frame
(first_frame.py), the local fit (local_fit.py), a body left facing backwards (turned_round.py), limb recovery
(limb_recovery.py) and the checkpoint's plain data (checkpoint.py).
"""
import dataclasses
import time

import numpy as np

from ..blas_threads import blas_threads
from ..body.proxy import make_proxy
from ..body.rotations import rotvec_to_matrix
from ..capture.frames import DEFAULT_FPS
from ..energy.likelihood import default_pose_at
from ..evidence.view_presence import views_in_play
from ..optimizers import PoseSpace, make_optimizer
from .anchor import RootAnchor
from .checkpoint import optimizer_state, restore_optimizer
from .clothes_check import ClothesCheck
from .first_frame import (KEYPOINT_INIT_TRANSLATION, KEYPOINT_INIT_YAW, keypoint_start, neutral_joints,
                          search_first_frame)
from .first_frame_review import FirstFrameEvidence, reviewed
from .limb_recovery import LimbRecovery
from .local_fit import LocalFit
from .observation import FrameObserver, background_models, expected_poses, guide_after_search, guide_before_search
from .pulling_view import only_views, pulling_view, view_gains
from .root_gate import RootGate
from .settings import FrameEstimate, TrackingSettings
from .turned_round import TurnedRound

NEXT = object()  # Tracker.track's default next frame: the one after


def _record(per_frame, frame, value):
    """Keep `value` for `frame` in a report's per-frame record, or drop the frame's entry when it is empty."""
    if value:
        per_frame[int(frame)] = value
    else:
        per_frame.pop(int(frame), None)


class Tracker:
    """Tracks one subject through a capture. Call `initialise` once, then `track(frame)` per frame; `state()` is
    what a checkpoint keeps, `restore(state)` continues from it."""

    def __init__(self, body, capture, settings=None, prior=None, proxy=None, energy_model=None, dynamics=None):
        from ..energy.likelihood import REFINE_PERSON_PX, EnergyModel, energy_scale_for  # heavy (numba)

        self.body = body
        self.capture = capture
        self.settings = s = settings or TrackingSettings()
        self.proxy = proxy or make_proxy(body, s.proxy_triangles)
        scale = s.energy_scale
        if scale is None:  # the person (as the subject is placed) about 120 energy pixels tall
            scale = energy_scale_for(body, capture.cameras, body.default_pose())
        self.energy = energy_model or EnergyModel(body, self.proxy, capture.cameras, s.likelihood, prior=prior,
                                                  backend=s.backend, scale=scale, landmarks=s.landmarks)
        self.scale = self.energy.scale
        self.refine_scale = s.refine_scale
        if self.refine_scale is None:
            self.refine_scale = self.scale if not s.fine_refine else max(
                self.scale, energy_scale_for(body, capture.cameras, body.default_pose(), person_px=REFINE_PERSON_PX,
                                             largest=1.0))
        self.dynamics = dynamics
        if s.refine not in ("icp", "none"):
            raise ValueError(f"refine must be 'icp' or 'none', got {s.refine!r}")
        weights = self.energy.weights
        learned_mask = weights.needs_learned_evidence and weights.mask == "learned"
        self.backgrounds = background_models(capture, s.background, s.background_frames, build_now=not learned_mask)
        self.space = PoseSpace.with_default_scale(body.lower, body.upper, body.dof_names,
                                                  np.isin(np.arange(body.n_dof), body.translation_dofs))
        self.optimizer = make_optimizer(s.algorithm, self.space, budget=s.budget, seed=s.seed,
                                        **self._optimizer_kwargs())
        self.root = RootAnchor(body.root_rotation_dofs)
        scales = [self.scale] + ([self.refine_scale] if self.refines and self.refine_scale != self.scale else [])
        self.observer = FrameObserver(capture, body, self.backgrounds, scales, weights.needs_learned_evidence,
                                      weights.mask == "learned", diffuse=self.uses_color,
                                      clothes=s.check_clothes and weights.needs_learned_evidence,
                                      landmarks=s.landmarks)
        self.clothes = ClothesCheck() if self.observer.clothes else None
        self.local_fit = LocalFit(body, self.proxy, capture.cameras, self.energy, self.space, self.root, self.scale,
                                  self.refine_scale, s.refine_iterations)
        self.limb_recovery = LimbRecovery(body, capture.cameras, self.energy, self.space, self.root, s.seed,
                                          self._energy_fn, self.fit_locally if self.refines else None,
                                          self._particles_follow)
        fps = getattr(capture.frames, "fps", None) or DEFAULT_FPS
        self.root_gate = RootGate(self.space, body.translation_dofs, body.root_rotation_dofs, fps, s.seed,
                                  self.fit_locally if self.refines else None, self._particles_follow,
                                  self._leave_out_pulling_view)
        self.observation = None  # the frame loaded last (observation.Observation)
        self.views_in_play = None  # per camera, whether the image terms listen to it this frame
        self.views_left_out = {}  # {frame: [camera names]} left out of the image terms that frame
        self.keypoint_fit = None  # the first frame's landmark fit: {"points", "rms_m"}
        self.history = []  # relative poses of the solved frames (most recent last)
        self.turned = TurnedRound(body)
        self.turns = {}  # {frame: energies} where the estimate's turned-round reflection was kept
        self.next_guide = None  # (frame, absolute poses) the next frame's crops are placed around
        self.estimates = []
        self.others = None  # the other tracked actors this frame (other_actors.OtherActors), or None
        self.views_shared = {}  # {frame: [camera names]} whose evidence was another actor's
        self.landmarks_set_aside = {}  # {frame: {camera name: landmarks}} the other views disagreed with
        self.unlike_clothes = {}  # {frame: {camera name: likeness}} whose landmarks outlined other clothes
        self.first_evidence = None  # the searched first frame's evidence until the second frame reviews it
        self.first_frame_review = None  # what the review changed (first_frame_review.reviewed), or None

    def _optimizer_kwargs(self):
        s = self.settings
        kw = dict(s.optimizer_options)
        if s.algorithm == "isa":
            kw.setdefault("schedule", s.schedule)
            kw.setdefault("c", s.isa_mutation)
            kw.setdefault("c_pred", s.isa_prediction_covariance)
        if s.algorithm in ("isa", "apf"):
            spread = s.isa_prediction_spread if s.algorithm == "isa" else s.prediction_spread
            kw.setdefault("n", s.particles)
            kw.setdefault("velocity", s.velocity)
            kw.setdefault("sigma_pred", spread * self.body.scale)
            if s.velocity and self.dynamics is not None:  # the inter-frame shift's prediction
                kw.setdefault("dynamics", self.dynamics)
        if s.algorithm in ("pf", "fsa") and self.dynamics is not None:
            kw.setdefault("dynamics", self.dynamics)
        return kw

    @property
    def refines(self):
        return self.settings.refine == "icp" and self.settings.algorithm != "icp"

    @property
    def uses_color(self):
        return self.energy.weights.color > 0

    # ------------------------------------------------------------------ poses relative to the root anchor
    @property
    def anchor(self):
        return self.root.matrix

    @anchor.setter
    def anchor(self, matrix):
        self.root.matrix = np.asarray(matrix, dtype=np.float64)

    def to_absolute(self, poses):
        return self.root.to_absolute(poses)

    def to_relative(self, poses):
        return self.root.to_relative(poses)

    def _energy_fn(self, poses, weights=None):
        """The energy of relative poses (P,D) -> (P,); `weights`: other LikelihoodWeights than the model's."""
        return self.energy(self.to_absolute(poses), weights=weights)

    def _particles_follow(self, step):
        """Move the optimiser's particles by the step the estimate took after the search (kept within limits)."""
        self.optimizer.map_poses(lambda poses: self.space.clamp(poses + step), start=False)

    def _last_absolute(self, n):
        return [self.to_absolute(h) for h in self.history[-n:]]

    # ------------------------------------------------------------------ observing a frame
    @property
    def evidence(self):
        """The learned evidence of the frame loaded last (one ViewEvidence per camera), or None."""
        return None if self.observation is None else self.observation.evidence

    @property
    def fine_silhouettes(self):
        """The local fit's silhouettes of the frame loaded last, or None (it uses the energy's)."""
        return None if self.observation is None else self.observation.fine_silhouettes

    def features(self, frame, guide_poses=None):
        """The frame's ViewFeatures per camera; with learned evidence its crops are placed around `guide_poses`
        (absolute; by default where the person is expected). The frame becomes the one loaded last."""
        if guide_poses is None:
            guide_poses = expected_poses(self._last_absolute(2), self.body.default_pose())
        self.observation = self.observer.observe(frame, guide_poses)
        return self.observation.features

    def load_frame(self, frame, guide_poses=None):
        """Observe `frame` (crops around `guide_poses`, by default those planned for it or where the person is
        expected), hand it to the energy model and choose the views in play; returns the features."""
        if guide_poses is None:
            planned = self.next_guide
            guide_poses = planned[1] if planned is not None and planned[0] == int(frame) else expected_poses(
                self._last_absolute(2), self.body.default_pose())
        observation = self.observer.take(frame, guide_poses)
        self.observation = observation if observation is not None else self.observer.observe(frame, guide_poses)
        feats = self.observation.features
        self.energy.set_frame(feats, self.evidence)
        apart = self._set_apart_others(guide_poses)
        aside, taken = self._set_aside_disagreeing(guide_poses)
        unlike = self._set_aside_unlike(frame)
        names = [c.name for c in self.capture.cameras]
        # this frame's last observation decides (the first frame is observed twice: rough placement, then fitted)
        _record(self.views_shared, frame, [n for n, s in zip(names, apart | taken | unlike) if s])
        _record(self.landmarks_set_aside, frame, {n: int(k) for n, k in zip(names, aside) if k})
        predicted = self.body.joint_positions(np.atleast_2d(guide_poses))[-1]
        targets = self.energy.targets
        self.views_in_play = views_in_play(
            self.capture.cameras, predicted, self.evidence, silhouette_area=targets.observed_count,
            person_area=self.energy.reference_area, picture_area=np.multiply(targets.widths, targets.heights))
        self.energy.set_view_weights(self.views_in_play.astype(np.float64))
        if not self.views_in_play.all():
            self.views_left_out[int(frame)] = [c.name for c, keep in zip(self.capture.cameras, self.views_in_play)
                                               if not keep]
        return feats

    def set_others(self, others):
        """The other tracked actors for the next frame solved (other_actors.OtherActors; None: alone)."""
        self.others = others if others else None

    def _set_apart_others(self, guide_poses):
        """Mark the other actors' bodies in the energy's targets and drop the landmarks that are theirs; a view
        whose landmarks mostly were loses all of them this frame, its silhouettes still count with the others set
        apart (docs/defaults.md, "Several actors: a shared view"). Returns (C,) bool: those views."""
        from .other_actors import associate_landmarks

        shared = np.zeros(len(self.capture.cameras), dtype=bool)
        if self.others is None:
            return shared
        energy = self.energy
        energy.targets = energy.targets.with_others(self.others.masks(energy.cameras, energy.targets.silhouette.shape))
        if energy.keypoints is None:
            return shared
        own = energy.project_rig_points(np.atleast_2d(guide_poses)[-1:])[0]
        energy.keypoints, shared = associate_landmarks(
            energy.keypoints, own, self.others.landmark_points(self.capture.cameras), energy.rig_points.swap)
        return shared

    def _set_aside_disagreeing(self, guide_poses):
        """Drop the landmarks the other views (and the prediction) disagree with: another person's, given by the
        landmark model where that person stands in front of this actor; a view that loses most of its landmarks'
        weight so loses all of them this frame. Returns (C,) landmarks set aside per view, (C,) bool those views."""
        from ..evidence.landmark_consensus import set_aside_disagreeing

        energy = self.energy
        if energy.keypoints is None:
            n = len(self.capture.cameras)
            return np.zeros(n, dtype=int), np.zeros(n, dtype=bool)
        predicted = energy.rig_points.world(self.body, np.atleast_2d(guide_poses)[-1:])[0]
        energy.keypoints, aside, taken = set_aside_disagreeing(
            self.capture.cameras, energy.keypoints, energy.rig_points.swap, predicted)
        return aside.sum(axis=1), taken

    def _set_aside_unlike(self, frame):
        """Drop every landmark of the views whose landmarks outline someone dressed unlike the actor
        (clothes_check.py). Returns (C,) bool those views."""
        energy, n = self.energy, len(self.capture.cameras)
        if self.clothes is None or not self.clothes.ready or energy.keypoints is None or self.evidence is None:
            return np.zeros(n, dtype=bool)
        unlike, like = self.clothes.unlike(self.evidence)
        unlike &= energy.keypoints.weight.sum(axis=1) > 0
        if unlike.any():
            energy.keypoints = only_views(energy.keypoints, ~unlike)
        names = [c.name for c in self.capture.cameras]
        _record(self.unlike_clothes, frame, {m: round(float(v), 3) for m, v, u in zip(names, like, unlike) if u})
        return unlike

    def _learn_clothes(self):
        """The actor's clothes from the views whose landmarks the frame just solved kept."""
        if self.clothes is not None and self.energy.keypoints is not None:
            self.clothes.learn(self.evidence, self.energy.keypoints.weight.sum(axis=1) > 0)

    def _plan_next(self, frame, guide, observe):
        """Place the next frame's crops around `guide` (absolute poses), and observe that frame in the worker
        when `observe`. The plan is part of the state, so a resumed run places the crops as an unbroken one."""
        frame = int(frame)
        self.next_guide = (frame, guide)
        if observe and 0 <= frame < self.capture.frames.n_frames:
            self.observer.prefetch(frame, guide)

    def finish_prefetch(self):
        """Wait for a prefetch still running and stop the worker (before the capture is closed)."""
        self.observer.finish()

    # ------------------------------------------------------------------ the local fit
    def fit_locally(self, estimate):
        """The local fit of a relative pose on the frame loaded last."""
        return self.local_fit.fit(estimate, self.observation, self.views_in_play, self.others)

    def _refine(self, estimate):
        """The local fit of the search's estimate; the kept particles move by the same step."""
        fitted = self.fit_locally(estimate)
        self._particles_follow(fitted - estimate)
        return fitted

    # ------------------------------------------------------------------ tracking
    def initialise(self, frame, rough_pose=None, initial_pose=None):
        """First frame: a global search around the subject's rough placement (or a given pose)."""
        with blas_threads(1):
            return self._initialise(frame, rough_pose, initial_pose)

    def _initialise(self, frame, rough_pose, initial_pose):
        t0, c0 = time.perf_counter(), time.process_time()
        body, s = self.body, self.settings
        rough = body.default_pose() if rough_pose is None else np.asarray(rough_pose, float)
        self.root.matrix = rotvec_to_matrix(rough[body.root_rotation_dofs])
        self.energy.set_reference_pose(default_pose_at(body, rough))
        self.load_frame(frame, rough if initial_pose is None else initial_pose)
        if initial_pose is None:
            start = neutral_joints(body, getattr(self.energy, "prior", None), rough)
            half_width, yaw_spread = s.init_translation, s.init_yaw / 2
            fitted = None
            if self.evidence is not None:
                fitted, self.keypoint_fit = keypoint_start(body, self.capture.cameras, self.energy, start)
            if fitted is not None:  # the landmarks place the body: search closer around it
                start, half_width, yaw_spread = fitted, KEYPOINT_INIT_TRANSLATION, KEYPOINT_INIT_YAW
                self.load_frame(frame, fitted)  # crops around the person, not the rough placement
            # The colour model is made from this search's pose, so the search cannot use colour.
            without_colour = dataclasses.replace(self.energy.weights, color=0.0)
            estimate, evaluations = search_first_frame(
                body, self.space, s, lambda poses: self._energy_fn(poses, without_colour), self.to_relative(start),
                half_width, yaw_spread, polish=self.fit_locally if self.refines else None)
            estimate = self._refine(estimate) if self.refines else estimate
            pose = self.to_absolute(estimate)
            if self.refines:  # the review is a local fit: without one, nothing to keep the images for
                energy = self.energy
                self.first_evidence = FirstFrameEvidence(self.observation, energy.targets, energy.keypoints,
                                                         self.views_in_play.copy(), self.others)
        else:
            pose = np.asarray(initial_pose, float)
            evaluations = 0
        if self.uses_color:
            self.energy.init_color_model(pose)
        energy = float(self.energy(pose[None])[0])
        self.optimizer.start(self.to_relative(pose))
        self.root_gate.start(frame, pose[self.body.translation_dofs])
        self._learn_clothes()
        return self._record(frame, pose, energy, time.perf_counter() - t0, evaluations, time.process_time() - c0)

    def track(self, frame, next_frame=NEXT):
        """Solve one frame after the initial one. `next_frame`: the frame to observe meanwhile (default
        frame + 1; None when no frame follows)."""
        with blas_threads(1):  # the cores are the rasteriser's and the worker's (core/blas_threads.py)
            return self._track(frame, next_frame)

    def _track(self, frame, next_frame):
        t0, c0 = time.perf_counter(), time.process_time()
        self.load_frame(frame)
        upcoming = frame + 1 if next_frame is NEXT or next_frame is None else next_frame
        observe = self.settings.prefetch and next_frame is not None
        if self.settings.observe_early:  # a short search leaves the worker too little time after it
            self._plan_next(upcoming, guide_before_search(self._last_absolute(2)), observe)
        if hasattr(self.optimizer, "set_frame_problem"):  # ICP works on correspondences, not a black box
            self.optimizer.set_frame_problem(self.local_fit.problem(self.observation, self.views_in_play,
                                                                    others=self.others))
        result = self.optimizer.track_frame(self._energy_fn, list(self.history))
        estimate, energy, evaluations = result.estimate, result.energy, result.evaluations
        if not self.settings.observe_early:
            self._plan_next(upcoming, guide_after_search(self._last_absolute(1), self.to_absolute(estimate)), observe)
        if self.refines:
            estimate = self._refine(estimate)
            energy, evaluations = float(self._energy_fn(estimate[None])[0]), evaluations + 1
            # before the limbs are looked at: a body facing backwards would put each on the other's landmarks
            estimate, energy, evaluations = self._turn_round(estimate, energy, evaluations, frame)
        if self.evidence is not None:
            estimate, energy, evaluations = self.limb_recovery.recover(estimate, energy, evaluations, frame)
        # a root that moved faster than a person can is refused and the frame searched again (root_gate.py)
        estimate, energy, evaluations = self.root_gate.check(estimate, energy, evaluations, frame, self.history,
                                                             self._energy_fn)
        pose = self.to_absolute(estimate)
        lam = self.settings.color_adaptation
        lam = self.energy.weights.adaptation if lam is None else lam
        if self.uses_color and lam > 0:
            self.energy.adapt_color_model(pose, lam)
        self._learn_clothes()
        est = self._record(frame, pose, energy, time.perf_counter() - t0, evaluations, time.process_time() - c0)
        if self.first_evidence is not None:
            self._review_first_frame()
        self.history = self.root.follow(self.history[-1], self.optimizer, self.history)
        return est

    def _turn_round(self, estimate, energy, evaluations, frame):
        """The estimate's reflection through its frontal plane (turned_round.py), fitted locally, replaces it where
        its energy is lower: a body left facing backwards by a fast turn finds its way back."""
        mirrored = self.turned.reflected(self.to_absolute(estimate))
        if mirrored is None:
            return estimate, energy, evaluations
        candidate = self.fit_locally(self.to_relative(mirrored))
        candidate_energy = float(self._energy_fn(candidate[None])[0])
        evaluations += 1
        if not candidate_energy < energy:
            return estimate, energy, evaluations
        self.turns[int(frame)] = {"energy_before": float(energy), "energy_after": candidate_energy}
        self._particles_follow(candidate - estimate)
        self.history = [candidate] * len(self.history)  # the half turn is no motion to predict from
        return candidate, candidate_energy, evaluations

    def _leave_out_pulling_view(self, refused, predicted):
        """The root gate refused `refused`: the view that favours it most over `predicted` leaves this frame's image
        terms and landmarks (pulling_view.py). Returns the camera names left out."""
        energy = self.energy
        view = pulling_view(view_gains(energy, self._energy_fn, self.views_in_play, refused, predicted))
        if view is None:
            return []
        self.views_in_play = self.views_in_play.copy()
        self.views_in_play[view] = False
        energy.set_view_weights(self.views_in_play.astype(np.float64))
        if energy.keypoints is not None:
            energy.keypoints = only_views(energy.keypoints, self.views_in_play)
        return [self.capture.cameras[view].name]  # report.json's root_gate entry of the frame names it

    def _review_first_frame(self):
        """Once the second frame is solved: its pose fitted locally to the first frame's images replaces the first
        frame's pose where it explains them better and some joint moved far (first_frame_review.py). Without
        colour, as the first frame's search: its colour model was made from the pose under review."""
        first, self.first_evidence = self.first_evidence, None
        if len(self.estimates) != 2 or len(self.history) < 2:
            return
        energy = self.energy
        now = (self.observation, energy.targets, energy.keypoints, self.views_in_play, self.others)
        self.observation, energy.targets, energy.keypoints, self.views_in_play, self.others = (
            first.observation, first.targets, first.keypoints, first.views_in_play, first.others)
        energy.set_view_weights(first.views_in_play.astype(np.float64))
        try:
            without_colour = dataclasses.replace(energy.weights, color=0.0)
            before = self.history[-2]
            candidate = self.fit_locally(self.history[-1])
            scores = self._energy_fn(np.stack([before, candidate]), without_colour)
            candidate_energy = float(self._energy_fn(candidate[None])[0])  # as the first frame's was recorded
        finally:
            self.observation, energy.targets, energy.keypoints, self.views_in_play, self.others = now
            energy.set_view_weights(self.views_in_play.astype(np.float64))
        verdict = reviewed(self.body, self.to_absolute(before), scores[0], self.to_absolute(candidate), scores[1])
        if verdict is None:
            return
        est = self.estimates[0]
        est.pose = self.to_absolute(candidate)
        est.joints = self.body.joint_positions(est.pose[None])[0]
        est.energy = candidate_energy
        self.history[-2] = candidate
        self.first_frame_review = {"frame": int(est.frame), **verdict}

    @property
    def recoveries(self):
        """The limb searches so far: {"frame", "limbs", "kept"} each."""
        return self.limb_recovery.recoveries

    @property
    def gated(self):
        """The frames whose solution the root gate refused: {"frame", "speed_m_per_s", "kept_speed_m_per_s",
        "limit_m_per_s"} each."""
        return self.root_gate.gated

    def _record(self, frame, pose, energy, seconds, evaluations, cpu_seconds=None):
        self.history.append(self.to_relative(pose))
        self.history = self.history[-3:]
        joints = self.body.joint_positions(pose[None])[0]
        est = FrameEstimate(int(frame), pose, joints, float(energy), float(seconds), int(evaluations),
                            cpu_seconds=None if cpu_seconds is None else float(cpu_seconds))
        if self.evidence is not None:
            est.landmarks = np.stack([ev.keypoints for ev in self.evidence])
            est.landmark_visibility = np.stack([ev.visibility if ev.found else np.zeros_like(ev.visibility)
                                                for ev in self.evidence])
        self.estimates.append(est)
        return est

    # ------------------------------------------------------------------ checkpoints
    def state(self):
        """Everything needed to continue exactly where this tracker stands, as plain data (arrays, numbers,
        strings; core/tracking/checkpoint.py stores it)."""
        energy = self.energy
        return {"optimizer": optimizer_state(self.optimizer), "anchor": self.root.matrix,
                "history": list(self.history), "color_model": [energy.color_model, energy.color_count],
                "reference": [energy.reference_area, float(energy.reference_boundary)],
                "limb_off_frames": dict(self.limb_recovery.off_frames),
                "root_gate": self.root_gate.state(),
                "clothes": None if self.clothes is None else self.clothes.state(),
                "next_guide": None if self.next_guide is None else [int(self.next_guide[0]), self.next_guide[1]]}

    def restore(self, state):
        """Continue from `state` (state() of a tracker built with the same settings)."""
        restore_optimizer(self.optimizer, state["optimizer"])
        self.root.matrix = np.asarray(state["anchor"], dtype=np.float64)
        self.history = [np.asarray(h, dtype=np.float64) for h in state["history"]]
        area, boundary = state["reference"]
        self.energy.reference_area, self.energy.reference_boundary = np.asarray(area), float(boundary)
        self.energy.color_model, self.energy.color_count = state["color_model"]
        self.limb_recovery.off_frames = {str(k): int(v) for k, v in state.get("limb_off_frames", {}).items()}
        self.root_gate.restore(state.get("root_gate"))
        if self.clothes is not None:
            self.clothes.restore(state.get("clothes"))
        guide = state.get("next_guide")
        self.next_guide = None if guide is None else (int(guide[0]), np.asarray(guide[1], dtype=np.float64))


def run_tracker(tracker, frames, initial_pose=None, rough_pose=None, on_frame=None, should_stop=None):
    """Track `frames` (the first one initialises). Returns the list of FrameEstimates."""
    out = []
    try:
        for i, frame in enumerate(frames):
            if should_stop is not None and should_stop():
                break
            upcoming = frames[i + 1] if i + 1 < len(frames) else None
            est = tracker.initialise(frame, rough_pose=rough_pose, initial_pose=initial_pose) if i == 0 \
                else tracker.track(frame, next_frame=upcoming)
            out.append(est)
            if on_frame is not None:
                on_frame(est)
    finally:
        tracker.finish_prefetch()
    return out
