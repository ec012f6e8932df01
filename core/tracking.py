"""The per-frame tracking loop: initialise, predict, optimise, adapt colour, checkpoint.

The same loop serves the command line, the Blender modal operator and the tests. It never touches
Blender: it reads a Capture, scores poses with an EnergyModel and hands each frame's estimate to a
callback as soon as it is solved, so nothing solved is ever lost.

Root rotation (algorithms.md 1.4): the optimisers see the root rotation relative to an anchor
(the previous estimates' orientation), so the particle arithmetic stays Euclidean and never meets
the pi wrap of rotation vectors, even when the subject turns around. The anchor moves with the
subject; stored particles are re-expressed when it does.
"""
import dataclasses
import threading
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

import numpy as np

from .blas_threads import blas_threads
from .features import BackgroundModel, compute_view_features
from .features.mask_cleanup import check_mask
from .features.view_features import feature_size, resize_mask
from .likelihood import default_pose_at
from .limb_search import limb_dofs, search_limbs
from .optimizers import PoseSpace, make_optimizer
from .proxy import make_proxy
from .rotations import matrix_to_rotvec, rotvec_to_matrix
from .view_presence import views_in_play

NEXT = object()  # Tracker.track's default next frame: the one after
REANCHOR_ANGLE = np.deg2rad(20.0)
# First frame from keypoints: the global search then only needs to look this far around the fitted pose.
KEYPOINT_INIT_TRANSLATION = 0.08  # metres, half width
KEYPOINT_INIT_YAW = float(np.deg2rad(8.0))
KEYPOINT_INIT_MAX_RMS = 0.12  # metres: a worse fit means the landmarks disagree; keep the rough placement
# Recovery: a limb whose landmarks lie this far from it (median over views, in units of the person's size
# in the view) for this many frames in a row is searched again on its own [DESIGN].
RECOVERY_DISTANCE = 0.1
RECOVERY_FRAMES = 3
# The keypoint proposal also takes a limb whose elbow or wrist (knee or ankle) lies this far from its
# landmark triangulated over the views [DESIGN]: the per-view measure above is a median over views and
# points, each matched as the energy matches it (swaps, second guesses), and missed a hand lost by 0.3-0.4 m
# while one or two views agreed with the wrong place (busy, seed 1, frames 54-56: 0.06-0.07). The proposal
# is kept only when it lowers the energy, so a wrong triangulation costs time, not accuracy.
RECOVERY_DISTANCE_3D = 0.15  # metres
# The anatomical prior's weight in the local fit after the search (IcpSettings.prior_weight; the paper's ICP
# optimiser keeps lambda_anat = 2). At 2 it pulled fitted limbs towards common poses: started AT the true pose
# with the arms crossed (busy frame 40, tools/local_fit_from_truth.py) the fit walked the left wrist 0.12 m away,
# and without the prior it stayed within 0.04 m. Measured, default pipeline, whole clips, seeds 0-2, smoothed
# (walk / playground / busy / held-out dusk / lobby): at 2: 16.3 / 14.3 / 30.7 / 29.9 / 34.9 mm; at 1:
# 14.7 / 13.6 / 27.8 / 25.9 / 32.9; at 0.5: 13.9 / 13.4 / 27.3 / 24.4 / 31.1 (better on every scene); at 0.25:
# 13.5 / 13.1 / 26.8 / 23.6 / 32.1 (the held-out scenes split). The search's prior was 2 in all of these. With the
# search's prior at 1 (likelihood.DEFAULT_LIKELIHOOD_ANAT_WEIGHT): at 0.5: 13.9 / 13.3 / 25.2 / 23.8 / 31.4; at 0.25:
# 13.4 / 13.2 / 24.6 / 22.6 / 30.8 (the product's runs, session 18: every scene better), so 0.25; at 0: busy seed 0 28.7.
LOCAL_FIT_PRIOR_WEIGHT = 0.25
# Where the optimisers keep poses between frames (expressed relative to the anchor): these, and
# only these, are re-expressed when the anchor moves. Scales and floors must not be touched.
POSE_STATE_ATTRIBUTES = ("x0", "particles", "state", "hist")
PARTICLE_STATE_ATTRIBUTES = POSE_STATE_ATTRIBUTES[1:]  # what follows the estimate from frame to frame


@dataclass
class TrackingSettings:
    algorithm: str = "isa"
    # The product's default (README, "Where it stands": best on every sample scene); the paper's likelihoods
    # stay selectable for the comparison.
    likelihood: str = "lsilh+edge+kp"
    # The paper's split of its 3000 evaluations per frame. The same budget as 100 x 30 annealed the walk's
    # arms better (plain ISA s+e, compare from the search: 27.2 mm against 30.5 mm over seeds 0-8) and the
    # playground about as well (18.0 against 17.8 mm over seeds 0-8): `--particles 100 --iterations 30`.
    particles: int = 200
    iterations: int = 15
    seed: int = 0
    backend: str = "auto"
    energy_scale: float | None = None  # None: from the person's size in the views (likelihood.energy_scale_for)
    background: str = "auto"  # auto (plate if present, else median) | plate | median | mog2 | knn
    background_frames: int = 25
    proxy_triangles: int = 2000
    init_particles: int = 500
    init_iterations: int = 30
    init_translation: float = 0.25  # metres: half width of the initial search box
    init_yaw: float = float(np.deg2rad(35.0))
    # Then each limb on its own (core/limb_search.py): the 30-DOF search often leaves an arm in a wrong
    # basin; walk first frame, seeds 0-3: 46-88 mm -> 14-15 mm, about 15 s more, once per run.
    init_limbs: bool = True
    color_adaptation: float | None = None  # None: the likelihood's default
    # Shift the particles by the predicted motion between frames: ISA and APF use the tracker's AR(3)
    # dynamics when it has them (as the paper does for ISA), else constant velocity. Measured on the walk
    # (ISA s+e 200x15, frames 1-19 from the true first pose): constant velocity 55.8/69.0/52.4 mm
    # (seeds 0-2), AR(3) 35.1/38.4/42.3/42.9/61.1/42.2 mm (seeds 0-5); constant velocity extrapolates the
    # noise of weakly observed DOFs (arm twist, elbow), so the arms drifted frame after frame. APF
    # (s^Ch+c, compare from the search, seeds 0-2): constant velocity 62.6 / 71.1 mm (walk / playground),
    # AR(3) 51.7 / 59.1 mm.
    # [DESIGN] The paper's captures run at 50-60 fps; ours at 30 fps move twice as far per frame,
    # more than the inter-frame mutation alone covers (measured: without it ISA drifts off a walk).
    velocity: bool = True
    # Inter-frame mutation floor sigma_pred as a multiple of the per-DOF scale (20 mm, 5 degrees), for APF.
    # Like ISA's, tighter tracks better (APF s^Ch+c with AR(3), compare from the search, seeds 0-2): 0.5 gave
    # walk 51.7 / playground 59.1 mm, 0.25 gives 49.5 / 47.4 mm.
    prediction_spread: float = 0.25
    # ISA's own spreads: mutation covariance c x the particles' sample covariance, inter-frame covariance
    # c_pred x that of the kept particles plus sigma_pred = isa_prediction_spread x scale. The search
    # wastes its budget when it keeps exploring: measured on the walk (ISA s+e 200x15, frames 1-19 from the
    # true first pose, seeds 0-5, error over every bone head), c, c_pred, spread = 0.5, 1.0, 0.5: 46.2 mm;
    # 0.3, 1.0, 0.5: 39.2; 0.3, 1.0, 0.25: 37.8; 0.3, 0.5, 0.25: 34.5; 0.3, 0.3, 0.15: 37.4; spread 1.0:
    # 80.6; a diagonal covariance: 127. The first-frame search keeps the class defaults.
    isa_mutation: float = 0.3
    isa_prediction_covariance: float = 0.5
    isa_prediction_spread: float = 0.25
    # ISA annealing: "ess" picks each beta so the effective sample size falls from 0.5 to 0.1 of the
    # particles (algorithms.md 2.4, the documented fallback); "polynomial" is beta0 (m+1)^b with the
    # [LIT?] constants 8 and 0.7. Measured on the walk scene (ISA s+e, 20 frames from the true first
    # pose): mean 3D error 56 mm (ess) vs 63 mm (polynomial); without the prior 52 vs 56 mm.
    schedule: str = "ess"
    # Local refinement after the search [DESIGN, after Gall et al.'s multi-layer framework, IJCV 2010: a
    # global stochastic optimisation, then a local fit]: "icp" runs ICP with twists (silhouette rims) from
    # the optimiser's estimate and moves the particles with it; "none" keeps the plain optimiser, as the
    # paper's comparison does. Measured on the walk (ISA s+e 200x15, frames 1-19 from the true first
    # pose, seeds 0-2, with the older, wider ISA spreads): 39.0/31.1/28.9 mm plain, 23.5/20.7/19.4 mm
    # refined. With the current spreads (compare from the search, seeds 0-2) walk 28.6 -> 20.8 mm, and the
    # playground ties at 17.9 mm. The particles settle the ambiguous directions (which arm is where); the
    # local fit then gets below the truth's energy where the particles stop short.
    refine: str = "icp"
    # The local fit looks at finer silhouettes than the search: None picks the resolution at which the
    # person's joints span about likelihood.REFINE_PERSON_PX pixels (at most the footage's), from the
    # person's size in the views as the energy resolution is.
    refine_scale: float | None = None
    # False: the local fit on the search's own silhouettes (refine_scale = the energy scale; the preview preset).
    fine_refine: bool = True
    # Iterations of each local fit (None: IcpSettings' 10); its correspondence distance halves over them as
    # over the default's (every 3 of 10 iterations).
    refine_iterations: int | None = None
    # Observe frame t+1 (read, learned evidence, features) in a worker thread during frame t's local fit;
    # the same result either way.
    prefetch: bool = True
    # Place (and observe) frame t+1's crops before frame t's search rather than after it (see
    # Tracker._guide_before_search): for searches too short to hide the observation behind the local fit.
    observe_early: bool = False
    optimizer_options: dict = field(default_factory=dict)

    @property
    def budget(self):
        return self.particles * self.iterations

    @classmethod
    def preset(cls, name, **overrides):
        """Settings of a named preset (PRESETS), then `overrides` (None values ignored)."""
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; presets are {sorted(PRESETS)}")
        values = {**PRESETS[name], **{k: v for k, v in overrides.items() if v is not None}}
        return cls(**values)

    def to_dict(self):
        return asdict(self)


# Named settings. "full": the paper's budget with the local fit on finer silhouettes (the default).
# "preview": for a quick look at a take, a sixtieth of the search (50 particles x 4 iterations) and the local
# fit at the search's resolution; the landmarks and the local fit do most of the work there (README,
# "Speed": its seconds per frame and accuracy on every sample scene).
PRESETS = {
    "full": {},
    "preview": {"particles": 50, "iterations": 4, "fine_refine": False, "refine_iterations": 6,
                "observe_early": True},
}


@dataclass
class FrameEstimate:
    frame: int
    pose: np.ndarray  # absolute DOF vector
    joints: np.ndarray  # (B,3) world bone heads
    energy: float
    seconds: float
    evaluations: int
    # The learned landmarks the frame was solved with, per camera: (C,33,2) image pixels and (C,33)
    # visibility (0 where a view had none); None without learned evidence.
    landmarks: np.ndarray | None = None
    landmark_visibility: np.ndarray | None = None
    # Process CPU time (every thread) while the frame was solved, the next frame's observation included: the
    # ratio to `seconds` shows both cores at work, and a slow frame with the usual CPU time points at a
    # machine shared with other work, not at the tracker (README, "Speed").
    cpu_seconds: float | None = None


class LazyBackgrounds(Mapping):
    """Camera name -> BackgroundModel, each made by make(read(name)) when first asked for (under a lock: the
    prefetch worker may ask). build_all() makes the missing ones at once: their frames read one camera after
    the other (the capture's reader serves one thread), then the clip medians two cameras at a time (NumPy
    work that releases the GIL)."""

    def __init__(self, names, read, make, ready=None):
        self._names = list(names)
        self._read, self._make = read, make
        self._models = dict(ready or {})
        self._lock = threading.Lock()

    def __getitem__(self, name):
        with self._lock:
            if name not in self._models:
                if name not in self._names:
                    raise KeyError(name)
                self._models[name] = self._make(self._read(name))
            return self._models[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def build_all(self):
        from concurrent.futures import ThreadPoolExecutor

        with self._lock:
            missing = [n for n in self._names if n not in self._models]
            if missing:
                frames = [self._read(n) for n in missing]
                with ThreadPoolExecutor(max_workers=min(2, len(missing))) as pool:
                    self._models.update(zip(missing, pool.map(self._make, frames)))

    @property
    def built(self):
        """Names of the cameras whose model exists."""
        return [n for n in self._names if n in self._models]


class Tracker:
    """Tracks one subject through a capture. Call `initialise` once, then `track(frame)` per frame."""

    def __init__(self, body, capture, settings=None, prior=None, proxy=None, energy_model=None, dynamics=None):
        from .likelihood import EnergyModel  # heavy (numba): import when a tracker is made

        self.body = body
        self.capture = capture
        self.settings = settings or TrackingSettings()
        self.proxy = proxy or make_proxy(body, self.settings.proxy_triangles)
        from .likelihood import REFINE_PERSON_PX, energy_scale_for

        scale = self.settings.energy_scale
        if scale is None:  # the person (as the subject is placed) about 120 energy pixels tall
            scale = energy_scale_for(body, capture.cameras, body.default_pose())
        kwargs = {"scale": scale}
        self.energy = energy_model or EnergyModel(body, self.proxy, capture.cameras, self.settings.likelihood,
                                                  prior=prior, backend=self.settings.backend, **kwargs)
        self.scale = self.energy.scale
        self.refine_scale = self.settings.refine_scale
        if self.refine_scale is None:
            self.refine_scale = self.scale if not self.settings.fine_refine else max(
                self.scale, energy_scale_for(body, capture.cameras, body.default_pose(), person_px=REFINE_PERSON_PX,
                                             largest=1.0))
        self.fine_silhouettes = None
        self.dynamics = dynamics
        if self.settings.refine not in ("icp", "none"):
            raise ValueError(f"refine must be 'icp' or 'none', got {self.settings.refine!r}")
        self.backgrounds = self._background_models()
        self.space = PoseSpace.with_default_scale(body.lower, body.upper, body.dof_names,
                                                  np.isin(np.arange(body.n_dof), body.translation_dofs))
        self.optimizer = make_optimizer(self.settings.algorithm, self.space, budget=self.settings.budget,
                                        seed=self.settings.seed, **self._optimizer_kwargs())
        self.anchor = np.eye(3)
        self.landmark_model = None  # loaded on first use (learned-evidence likelihoods)
        self.evidence = None
        self.keypoint_fit = None
        self.limb_off_frames = {}  # limb -> frames in a row its keypoints disagreed
        self.recoveries = []
        self.views_left_out = {}  # {frame: [camera names]} left out of the image terms that frame
        self.proposals = []
        self.history = []  # relative poses of the solved frames (most recent last)
        self.next_guide = None  # (frame, absolute poses) the next frame's crops are placed around
        self._pool = None  # the prefetch worker
        self._prefetched = None  # (frame, guide, future)
        self.estimates = []

    # ------------------------------------------------------------------ set-up
    def _optimizer_kwargs(self):
        s = self.settings
        kw = dict(s.optimizer_options)
        if s.algorithm == "isa":
            for key, value in self._schedule_kwargs().items():
                kw.setdefault(key, value)
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

    def _schedule_kwargs(self):
        return {"schedule": self.settings.schedule}

    def _background_models(self):
        """Each camera's BackgroundModel: from its plate, else from the clip (the median of frames spread over
        it). A clip median costs seconds per camera on HD footage and is only needed where the learned mask is
        not used (the paper's likelihoods, a view whose crop lost the person), so with the learned mask it is
        built when first asked for; otherwise now, the cameras on both cores."""
        cap, mode = self.capture, self.settings.background
        plates = {}
        for cam in cap.cameras:
            plate = (cap.backgrounds or {}).get(cam.name)
            if mode in ("auto", "plate") and plate is not None:
                plates[cam.name] = BackgroundModel.from_plate(plate)
            elif mode == "plate":
                raise FileNotFoundError(f"no background plate for camera {cam.name!r}: expected "
                                        f"background/{cam.name}.png in the capture, or use --background median")
        method = "median" if mode == "auto" else mode
        models = LazyBackgrounds([c.name for c in cap.cameras], self._background_frames,
                                 lambda frames: BackgroundModel.from_frames(frames, method=method), plates)
        weights = self.energy.weights
        if not (weights.needs_learned_evidence and weights.mask == "learned"):
            models.build_all()  # the cameras without a plate (none: nothing to do)
        return models

    def _background_frames(self, name):
        """The frames a clip-median background of camera `name` is made from: spread over the whole clip."""
        n = self.capture.frames.n_frames
        picks = np.unique(np.linspace(0, n - 1, min(self.settings.background_frames, n)).round().astype(int))
        return [self.capture.frames.read_camera(name, int(f)) for f in picks]

    def features(self, frame, guide_poses=None):
        """The frame's ViewFeatures per camera; with learned evidence, also sets self.evidence (one
        ViewEvidence per camera, the model's crops placed around `guide_poses`: the poses the person is
        expected near, absolute)."""
        if guide_poses is None:
            guide_poses = self._guide_poses()
        return self._use(self._observe_frame(frame, guide_poses))

    def _use(self, observation):
        feats, self.evidence, self.fine_silhouettes = observation
        return feats

    def _observe_frame(self, frame, guide_poses):
        """(features, evidence, fine silhouettes) of `frame`, reading nothing of the tracker's state but the
        capture, the background models and the landmark model: it may run in the prefetch thread."""
        images = self.capture.frames.read(frame)
        cams = self.capture.cameras
        evidence = None
        if self.energy.weights.needs_learned_evidence:
            evidence = self.observe(images, guide_poses)
        learned = evidence if evidence is not None and self.energy.weights.mask == "learned" else [None] * len(cams)
        scales = [self.scale] + ([self.refine_scale] if self.refines and self.refine_scale != self.scale else [])
        masks = []  # per camera: a silhouette per scale
        for cam, ev in zip(cams, learned):
            shape = images[cam.name].shape
            if ev is not None and ev.found:  # the model's mask, sampled straight at each feature resolution
                masks.append([ev.mask_at(feature_size(shape, s)) for s in scales])
            else:
                sil = check_mask(self.backgrounds[cam.name].silhouette(images[cam.name]))
                masks.append([resize_mask(sil, feature_size(shape, s)) for s in scales])
        fine = [m[1] for m in masks] if len(scales) > 1 else None
        feats = [compute_view_features(images[cam.name], None, scale=self.scale, diffuse=self.uses_color,
                                       silhouette=m[0])
                 for cam, m in zip(cams, masks)]
        return feats, evidence, fine

    # ---- the next frame, observed while this one is finished
    # The learned evidence (the landmark model: a tenth of a second on both cores) and the features of frame
    # t+1 need only where the person will be: the crops are placed around the search's estimate of frame t
    # (before the local fit, which moves it by a centimetre or two within crops 1.35 x the body), so they are
    # computed in a worker thread while the main thread runs the local fit, which uses one core.
    # With `observe_early` (the preview preset) they are placed before frame t's search, around the last two
    # frames' steps carried on to t and t+1: a short search leaves the worker too little time after it, and
    # the main thread waited for the worker (HD footage: 0.1 s of each 0.27 s frame, README "Speed").
    def _guide_after_search(self, searched):
        """Frame t+1's crops: around the search's estimate of t and one more step of the same size."""
        return carried_on([self.to_absolute(h) for h in self.history[-1:]] + [self.to_absolute(searched)], (0, 1))

    def _guide_before_search(self):
        """Frame t+1's crops before frame t is solved: the last step carried on to t and to t+1."""
        return carried_on([self.to_absolute(h) for h in self.history[-2:]], (1, 2))

    def _plan_next(self, frame, guide, observe):
        """Place the next frame's crops around `guide` (absolute poses), and observe that frame in the worker
        when `observe`. The plan is kept in the tracker's state, so a resumed run places the crops as an
        uninterrupted one did."""
        frame = int(frame)
        self.next_guide = (frame, guide)
        if not observe or not 0 <= frame < self.capture.frames.n_frames:
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mocap-observe")
        self._prefetched = (frame, guide, self._pool.submit(self._observe_frame, frame, guide))

    def _take_prefetched(self, frame, guide_poses):
        """The prefetched observation of `frame` around `guide_poses`, or None. Waits for any prefetch still
        running (the frame reader and the landmark model serve one thread at a time)."""
        pending, self._prefetched = self._prefetched, None
        if pending is None:
            return None
        p_frame, p_guide, future = pending
        if p_frame != int(frame) or p_guide is not guide_poses:
            try:
                future.result()
            except Exception:  # noqa: BLE001  (a frame nobody asks for: its error does not matter)
                pass
            return None
        return future.result()

    def finish_prefetch(self):
        """Wait for a prefetch still running and stop the worker (before the capture is closed)."""
        self._take_prefetched(-1, None)
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def observe(self, images, guide_poses):
        """Learned evidence per view, from crops around the projected joints of `guide_poses`."""
        from .evidence_crops import evidence_around
        from .features.learned import LandmarkModel

        if self.landmark_model is None:
            self.landmark_model = LandmarkModel()
        cams = self.capture.cameras
        frames = [images[cam.name] for cam in cams]
        return evidence_around(self.landmark_model, self.body, cams, frames, guide_poses,
                               foreground=lambda i: self.backgrounds[cams[i].name].silhouette(frames[i]))

    def _guide_poses(self):
        """Where the person is expected this frame: the last estimate and its constant-velocity step."""
        if not self.history:
            return self.body.default_pose()[None]  # nothing solved yet: the subject as placed
        return carried_on([self.to_absolute(h) for h in self.history[-2:]], (0, 1))

    def load_frame(self, frame, guide_poses=None):
        """Compute `frame`'s features (and learned evidence, crops around `guide_poses`, by default the
        prediction from the last estimates) and hand them to the energy model; returns the features."""
        if guide_poses is None:
            planned = self.next_guide
            guide_poses = planned[1] if planned is not None and planned[0] == int(frame) else self._guide_poses()
        observation = self._take_prefetched(frame, guide_poses)
        feats = self._use(observation if observation is not None else self._observe_frame(frame, guide_poses))
        self.energy.set_frame(feats, self.evidence)
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

    @property
    def uses_color(self):
        return self.energy.weights.color > 0

    # ------------------------------------------------------------------ root anchoring
    def to_absolute(self, poses):
        poses = np.array(poses, dtype=np.float64, copy=True)
        rd = self.body.root_rotation_dofs
        poses[..., rd] = matrix_to_rotvec(rotvec_to_matrix(poses[..., rd]) @ self.anchor)
        return poses

    def to_relative(self, poses, anchor=None):
        anchor = self.anchor if anchor is None else anchor
        poses = np.array(poses, dtype=np.float64, copy=True)
        rd = self.body.root_rotation_dofs
        poses[..., rd] = matrix_to_rotvec(rotvec_to_matrix(poses[..., rd]) @ anchor.T)
        return poses

    def _energy_fn(self, poses):
        return self.energy(self.to_absolute(poses))

    def _reanchor(self, relative_estimate):
        """Move the anchor onto the latest estimate; re-express every stored pose array."""
        rd = self.body.root_rotation_dofs
        if np.linalg.norm(relative_estimate[rd]) < REANCHOR_ANGLE:
            return
        old = self.anchor
        new = rotvec_to_matrix(relative_estimate[rd]) @ old
        self.anchor = new

        def convert(poses):
            return self.to_relative(self.to_absolute_with(poses, old), new)

        self._map_pose_state(convert)
        self.history = [convert(h) for h in self.history]

    def _map_pose_state(self, convert, names=POSE_STATE_ATTRIBUTES):
        """Apply `convert` to every pose array the optimiser keeps between frames."""
        opt = self.optimizer
        for name in names:
            value = getattr(opt, name, None)
            if isinstance(value, np.ndarray):
                setattr(opt, name, convert(value))
            elif isinstance(value, tuple) and value and isinstance(value[0], np.ndarray):  # APF: (X, weights)
                setattr(opt, name, (convert(value[0]),) + value[1:])

    def to_absolute_with(self, poses, anchor):
        saved, self.anchor = self.anchor, anchor
        try:
            return self.to_absolute(poses)
        finally:
            self.anchor = saved

    # ------------------------------------------------------------------ tracking
    def initialise(self, frame, rough_pose=None, initial_pose=None):
        """First frame: a global ISA search around the subject's rough placement (or a given pose)."""
        with blas_threads(1):
            return self._initialise(frame, rough_pose, initial_pose)

    def _initialise(self, frame, rough_pose, initial_pose):
        t0, c0 = time.perf_counter(), time.process_time()
        body, s = self.body, self.settings
        rough = body.default_pose() if rough_pose is None else np.asarray(rough_pose, float)
        self.anchor = rotvec_to_matrix(rough[body.root_rotation_dofs])
        self.energy.set_reference_pose(default_pose_at(body, rough))
        feats = self.load_frame(frame, rough if initial_pose is None else initial_pose)
        if initial_pose is None:
            from .optimizers.isa import InteractingSimulatedAnnealing

            searcher = InteractingSimulatedAnnealing(self.space, seed=s.seed, n=min(s.particles, s.init_particles),
                                                     **self._schedule_kwargs())
            start, half_width, yaw_spread = self._neutral_joints(rough), s.init_translation, s.init_yaw / 2
            fitted = self._keypoint_start(start) if self.evidence is not None else None
            if fitted is not None:  # the landmarks place the body: search closer around it
                start, half_width, yaw_spread = fitted, KEYPOINT_INIT_TRANSLATION, KEYPOINT_INIT_YAW
                feats = self.load_frame(frame, fitted)  # crops around the person, not the rough placement
            x0 = self.to_relative(start)
            spread = self.space.scale * 4  # joints: 20 degrees around the neutral posture
            tilt, yaw = body.root_rotation_dofs[:2], body.root_rotation_dofs[2]  # rotation vector in world axes, Z up
            spread[tilt] = np.deg2rad(8.0)
            spread[yaw] = yaw_spread
            weights = self.energy.weights
            # The colour model is built from the initial pose, so the search for it cannot use colour.
            self.energy.weights = dataclasses.replace(weights, color=0.0)
            try:
                result = searcher.global_init(
                    self._energy_fn, x0, spread, n=s.init_particles, iterations=s.init_iterations,
                    joints="around", translation_dofs=body.translation_dofs,
                    translation_half_width=half_width, yaw_dof=None)
                estimate, evaluations = result.estimate, result.evaluations
                if s.init_limbs:
                    polish = (lambda pose: self._icp_fit(feats, pose)) if self.refines else None
                    estimate, _, used = search_limbs(self._energy_fn, self.space, estimate, limb_dofs(body.dofs),
                                                     seed=s.seed, polish=polish)
                    evaluations += used
            finally:
                self.energy.weights = weights
            estimate = self._refine(feats, estimate) if self.refines else estimate
            pose = self.to_absolute(estimate)
        else:
            pose = np.asarray(initial_pose, float)
            evaluations = 0
        if self.uses_color:
            self.energy.init_color_model(pose)
        energy = float(self.energy(pose[None])[0])
        self.optimizer.start(self.to_relative(pose))
        return self._record(frame, pose, energy, time.perf_counter() - t0, evaluations, time.process_time() - c0)

    def _keypoint_start(self, start):
        """The first frame's pose from the triangulated landmarks (core/keypoint_fit.py), or None when too
        few landmarks triangulate or the fit leaves them far apart."""
        from .keypoint_fit import pose_from_keypoints

        pose, n_points, rms = pose_from_keypoints(self.body, self.capture.cameras, self.energy.keypoints,
                                                  self.energy.rig_points, start)
        self.keypoint_fit = {"points": n_points, "rms_m": rms}
        return pose if n_points >= 6 and rms < KEYPOINT_INIT_MAX_RMS else None

    def _neutral_joints(self, rough):
        """The rough placement with the joints of a typical posture: the per-DOF median of the prior's
        training poses (a person standing or walking), not the rig's rest pose (often an A- or T-pose)."""
        prior = getattr(self.energy, "prior", None)
        x = np.array(rough, dtype=np.float64)
        if prior is not None:
            for group, idx in prior.groups.items():
                x[idx] = np.median(prior.samples[group], axis=0)
        return self.body.clamp(x)

    def track(self, frame, next_frame=NEXT):
        """Solve one frame after the initial one. `next_frame`: the frame to observe meanwhile (default
        frame + 1; None when no frame follows)."""
        with blas_threads(1):  # the cores are the rasteriser's and the worker's (core/blas_threads.py)
            return self._track(frame, next_frame)

    def _track(self, frame, next_frame):
        t0, c0 = time.perf_counter(), time.process_time()
        feats = self.load_frame(frame)
        upcoming = frame + 1 if next_frame is NEXT or next_frame is None else next_frame
        observe = self.settings.prefetch and next_frame is not None
        if self.settings.observe_early:
            self._plan_next(upcoming, self._guide_before_search(), observe)
        if hasattr(self.optimizer, "set_frame_problem"):  # ICP works on correspondences, not a black box
            self.optimizer.set_frame_problem(self._icp_problem(feats))
        result = self.optimizer.track_frame(self._energy_fn, list(self.history))
        estimate, energy, evaluations = result.estimate, result.energy, result.evaluations
        if not self.settings.observe_early:
            self._plan_next(upcoming, self._guide_after_search(estimate), observe)
        if self.refines:
            estimate = self._refine(feats, estimate)
            energy, evaluations = float(self._energy_fn(estimate[None])[0]), evaluations + 1
        if self.evidence is not None:
            estimate, energy, evaluations = self._recover_limbs(feats, estimate, energy, evaluations, frame)
        pose = self.to_absolute(estimate)
        lam = self.settings.color_adaptation
        lam = self.energy.weights.adaptation if lam is None else lam
        if self.uses_color and lam > 0:
            self.energy.adapt_color_model(pose, lam)
        est = self._record(frame, pose, energy, time.perf_counter() - t0, evaluations, time.process_time() - c0)
        self._reanchor(self.history[-1])
        return est

    def _keypoint_proposal(self, feats, estimate, energy, evaluations, off):
        """The limbs whose landmarks disagree with the estimate this frame, fitted to the triangulated
        landmarks and polished by the local fit: kept when that lowers the energy (fast limbs outrun the
        particles' prediction; the detections do not). The fit starts from the estimate and from the limbs at
        rest (limb_landmark_fit)."""
        from .keypoint_fit import limb_distances_3d, limb_landmark_fit, triangulated_landmarks

        limbs = limb_dofs(self.body.dofs)
        X, ok = triangulated_landmarks(self.capture.cameras, self.energy.keypoints, self.energy.rig_points)
        if ok.sum() < 6:
            return estimate, energy, evaluations
        rig = self.energy.rig_points
        off_3d = limb_distances_3d(rig, rig.world(self.body, self.to_absolute(estimate)[None])[0], X, ok)
        off_limbs = [limb for limb in limbs if off.get(limb, 0.0) > RECOVERY_DISTANCE
                     or off_3d.get(limb, 0.0) > RECOVERY_DISTANCE_3D]
        if not off_limbs:
            return estimate, energy, evaluations
        dofs = np.concatenate([limbs[limb] for limb in off_limbs])
        candidate = self.to_relative(limb_landmark_fit(self.body, rig, self.to_absolute(estimate), X, ok, dofs))
        if self.refines:
            candidate = self._icp_fit(feats, candidate)
        candidate_energy = float(self._energy_fn(candidate[None])[0])
        evaluations += 1
        if candidate_energy < energy:
            step = candidate - estimate
            self._map_pose_state(lambda poses: self.space.clamp(poses + step), PARTICLE_STATE_ATTRIBUTES)
            self.proposals.append({"limbs": off_limbs, "kept": True})
            return candidate, candidate_energy, evaluations
        self.proposals.append({"limbs": off_limbs, "kept": False})
        return estimate, energy, evaluations

    def _limbs_off(self, estimate):
        from .keypoints import limb_disagreement

        pose = self.to_absolute(estimate)
        return limb_disagreement(self.energy.project_rig_points(pose[None])[0], self.energy.keypoints,
                                 self.energy.rig_points)

    def _recover_limbs(self, feats, estimate, energy, evaluations, frame):
        """First the limbs' keypoint proposal; then search again, each on its own, the limbs whose keypoints
        have disagreed for RECOVERY_FRAMES frames."""
        estimate, energy, evaluations = self._keypoint_proposal(feats, estimate, energy, evaluations,
                                                                self._limbs_off(estimate))
        off = self._limbs_off(estimate)
        for limb, distance in off.items():
            self.limb_off_frames[limb] = self.limb_off_frames.get(limb, 0) + 1 if distance > RECOVERY_DISTANCE else 0
        lost = {limb: idx for limb, idx in limb_dofs(self.body.dofs).items()
                if self.limb_off_frames.get(limb, 0) >= RECOVERY_FRAMES}
        if not lost:
            return estimate, energy, evaluations
        polish = (lambda p: self._icp_fit(feats, p)) if self.refines else None
        found, found_energy, used = search_limbs(self._energy_fn, self.space, estimate, lost,
                                                 seed=self.settings.seed + 7919 * int(frame), polish=polish)
        self.recoveries.append({"frame": int(frame), "limbs": sorted(lost), "kept": bool(found_energy < energy)})
        for limb in lost:
            self.limb_off_frames[limb] = 0
        if found_energy < energy:
            step = found - estimate
            self._map_pose_state(lambda poses: self.space.clamp(poses + step), PARTICLE_STATE_ATTRIBUTES)
            return found, float(found_energy), evaluations + used
        return estimate, energy, evaluations + used

    @property
    def refines(self):
        return self.settings.refine == "icp" and self.settings.algorithm != "icp"

    def _icp_fit(self, feats, estimate):
        from .optimizers.icp import IcpSettings, IcpSolver

        fine = self.fine_silhouettes is not None
        settings = IcpSettings(prior_weight=LOCAL_FIT_PRIOR_WEIGHT)
        if self.settings.refine_iterations is not None:
            settings = settings.with_iterations(self.settings.refine_iterations)
        settings = settings.at_resolution(self.refine_scale / self.scale) if fine else settings
        return IcpSolver(self._icp_problem(feats, fine), self.space, settings).fit(estimate).pose

    def _refine(self, feats, estimate):
        """ICP from the optimiser's (relative) estimate; the kept particles move by the same step."""
        fitted = self._icp_fit(feats, estimate)
        step = fitted - estimate
        self._map_pose_state(lambda poses: self.space.clamp(poses + step), PARTICLE_STATE_ATTRIBUTES)
        return fitted

    def _icp_problem(self, feats, fine=False):
        """The frame for ICP: at the energy resolution, or (fine) on the refinement's silhouettes."""
        from .optimizers.icp import IcpProblem

        scale = self.refine_scale if fine else self.scale
        cameras = [c.scaled(scale) for c in self.capture.cameras]
        silhouettes = self.fine_silhouettes if fine else [f.silhouette for f in feats]
        keypoints = self.energy.keypoints if self.evidence is not None and self.energy.weights.keypoint else None
        return IcpProblem(body=self.body, proxy=self.proxy, cameras=cameras,
                          silhouettes=self._without_left_out_views(silhouettes), to_absolute=self.to_absolute,
                          prior=getattr(self.energy, "prior", None),
                          keypoints=None if keypoints is None else keypoints.scaled(scale),
                          rig_points=self.energy.rig_points if keypoints is not None else None)

    def _without_left_out_views(self, silhouettes):
        """The silhouettes with those of the views left out this frame emptied: they offer ICP no contour."""
        in_play = getattr(self, "views_in_play", None)
        if in_play is None:
            return list(silhouettes)
        return [s if keep else np.zeros_like(s) for s, keep in zip(silhouettes, in_play)]

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
        """Everything needed to continue exactly where this tracker stands (picklable)."""
        return {"optimizer": self.optimizer, "anchor": self.anchor, "history": self.history,
                "color_model": (self.energy.color_model, self.energy.color_count),
                "reference": (self.energy.reference_area, self.energy.reference_boundary),
                "limb_off_frames": dict(self.limb_off_frames), "next_guide": self.next_guide}

    def restore(self, state):
        self.optimizer = state["optimizer"]
        self.anchor = state["anchor"]
        self.history = list(state["history"])
        self.energy.reference_area, self.energy.reference_boundary = state["reference"]
        self.energy.color_model, self.energy.color_count = state["color_model"]
        self.limb_off_frames = dict(state.get("limb_off_frames", {}))
        self.next_guide = state.get("next_guide")


def carried_on(last, steps):
    """Constant velocity: the poses (k+1) b - k a for each k in `steps`, from the last two poses [a, b];
    from one pose, that pose alone."""
    if len(last) < 2:
        return np.stack(last)
    a, b = last
    return np.stack([(1 + k) * b - k * a for k in steps])


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
