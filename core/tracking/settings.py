"""The tracker's settings (TrackingSettings, the named PRESETS) and what it hands out per frame (FrameEstimate)."""
from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass
class TrackingSettings:
    """How a take is tracked. The defaults are the product's; what each was measured against is in docs/defaults.md
    under the setting's name."""

    algorithm: str = "isa"
    # The learned evidence with the silhouettes and edges, best on every sample scene (docs/defaults.md,
    # "likelihood"); the paper's likelihoods stay selectable for the comparison.
    likelihood: str = "lsilh+edge+kp"
    # The paper's split of its 3000 evaluations per frame; 100 x 30 is as good or better (docs/defaults.md,
    # "particles").
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
    # Then each limb on its own (core/tracking/limb_search.py): the 30-DOF search often leaves an arm in a wrong
    # basin (docs/defaults.md, "init_limbs").
    init_limbs: bool = True
    color_adaptation: float | None = None  # None: the likelihood's default
    # Shift the particles by the predicted motion between frames (the AR(3) dynamics when given, else constant
    # velocity): at 30 fps a person moves further per frame than the mutation covers (docs/defaults.md, "velocity").
    velocity: bool = True
    # APF's inter-frame mutation floor, in per-DOF scales (20 mm, 5 degrees): tighter tracks better
    # (docs/defaults.md, "prediction_spread").
    prediction_spread: float = 0.25
    # ISA's spreads: mutation c x the particles' covariance; between frames c_pred x that of the kept particles
    # plus isa_prediction_spread x scale. A search that keeps exploring wastes its budget (docs/defaults.md,
    # "isa_mutation"); the first-frame search keeps the class defaults.
    isa_mutation: float = 0.3
    isa_prediction_covariance: float = 0.5
    isa_prediction_spread: float = 0.25
    # ISA annealing: "ess" picks each beta so the effective sample size falls from 0.5 to 0.1 of the particles
    # (algorithms.md 2.4); "polynomial" is beta0 (m+1)^b (docs/defaults.md, "schedule").
    schedule: str = "ess"
    # "icp": the local fit after the search (core/tracking/local_fit.py), the particles moved with it; "none": the
    # plain optimiser, as the paper's comparison runs it (docs/defaults.md, "refine").
    refine: str = "icp"
    # The local fit looks at finer silhouettes than the search: None picks the resolution at which the person's
    # joints span about likelihood.REFINE_PERSON_PX pixels (at most the footage's).
    refine_scale: float | None = None
    # False: the local fit on the search's own silhouettes (refine_scale = the energy scale; the preview preset).
    fine_refine: bool = True
    # Iterations of each local fit (None: IcpSettings' 10); its correspondence distance halves over them as
    # over the default's (every 3 of 10 iterations).
    refine_iterations: int | None = None
    # Observe frame t+1 (read, learned evidence, features) in a worker thread during frame t's local fit;
    # the same result either way.
    prefetch: bool = True
    # Set aside a view's landmarks where they outline someone dressed unlike the actor of the first frames
    # (core/tracking/clothes_check.py; docs/defaults.md, "MIN_LIKENESS").
    check_clothes: bool = True
    # Place (and observe) frame t+1's crops before frame t's search rather than after it: a short search leaves
    # the worker too little time after it (docs/defaults.md, "observe_early").
    observe_early: bool = False
    # The landmark model: BlazePose "heavy", or "full" (a third of heavy's time per crop, about a fifth less per
    # frame; heavy tracks better on every scene measured but two: docs/defaults.md, "landmarks").
    landmarks: str = "heavy"
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
# fit at the search's resolution; the landmarks and the local fit do most of the work there (docs/speed.md:
# its seconds per frame and accuracy on every sample scene). Its landmarks come from the full model: heavy's three
# times longer crops nearly double preview's time (docs/defaults.md, "landmarks").
PRESETS = {
    "full": {},
    "preview": {"particles": 50, "iterations": 4, "fine_refine": False, "refine_iterations": 6,
                "observe_early": True, "landmarks": "full"},
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
    # machine shared with other work, not at the tracker (docs/speed.md).
    cpu_seconds: float | None = None
