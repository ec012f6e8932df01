"""The tracking options a user chooses, in the Track panel or on the command line, from one place.

Each option's values come from the engine's own registries (the optimisers, the named likelihoods, the render
backends, the presets), its default from TrackingSettings; this module only adds the words a person reads (a
label and a line per value). The background models and the local fits are listed here: the tracker knows them
as branches, not as a table (tests/test_options.py builds each background offered). The panel's EnumProperty
items and the command line's choices are built from OPTIONS, and `settings_from_choices` is the one translation
of either's choices into TrackingSettings.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..energy.likelihood import LIKELIHOODS
from ..errors import InputError
from ..optimizers import available_optimizers
from ..render import BACKENDS
from .settings import PRESETS, TrackingSettings


class OptionError(InputError):
    """A tracking option set to a value it does not have; the message names the values it has."""


@dataclass(frozen=True)
class Choice:
    value: str
    label: str
    description: str


@dataclass(frozen=True)
class Option:
    name: str  # the TrackingSettings field, the panel property and the command line's --name
    label: str
    description: str
    default: object
    choices: tuple[Choice, ...] = ()  # empty: a number

    @property
    def values(self):
        return tuple(c.value for c in self.choices)

    def enum_items(self):
        """(identifier, name, description) per value, as Blender's EnumProperty takes them."""
        return tuple((c.value, c.label, c.description) for c in self.choices)

    def check(self, value):
        if self.choices and value not in self.values:
            raise OptionError(f"{self.name} {value!r} is not one of {', '.join(self.values)}")
        return value


# The words for the values the engine has today. A value the engine gains later is offered all the same, with
# words made from what the registry knows about it (its name; a likelihood's terms), until a line is written here.
_ALGORITHM_WORDS = {
    "isa": ("ISA", "Interacting simulated annealing: global optimisation with a particle set (the paper's best, "
                   "default)"),
    "apf": ("APF", "Annealed particle filter: layered annealing of a particle set"),
    "pf": ("PF", "Particle filter: one weighting step over many particles (weakest, for comparison)"),
    "fsa": ("FSA", "Fast simulated annealing: one hypothesis with Cauchy moves"),
    "icp": ("ICP", "Local refinement against silhouette contours: fast, loses fast motion"),
}
_LIKELIHOOD_WORDS = {
    "silh": ("Silhouette", "Binary silhouette overlap only"),
    "silh+edge": ("Silhouette + edges", "Binary silhouette overlap and image edges (the paper's best)"),
    "silh+edgech": ("Silhouette + chamfer edges", "Binary silhouette overlap and distance to image edges"),
    "silhch+color": ("Chamfer silhouette + colour", "Chamfer silhouette distance and per-part colour histograms "
                                                    "(slowest, best on clothes with distinct colours)"),
    "silhch": ("Chamfer silhouette", "Chamfer silhouette distance only"),
    "lsilh+edge": ("Learned mask + edges", "Silhouette from the learned person mask and image edges"),
    "silh+edge+kp": ("Silhouette + edges + keypoints",
                     "Background-subtraction silhouette, image edges and learned 2D body keypoints"),
    "lsilh+edge+kp": ("Learned mask + edges + keypoints",
                      "Silhouette from the learned person mask, image edges and learned 2D body keypoints (default: "
                      "robust to changing light, clutter and people in the background)"),
    "lsilh+kp": ("Learned mask + keypoints", "Learned person mask and learned 2D body keypoints"),
    "kp": ("Keypoints", "Learned 2D body keypoints only (with the anatomical prior)"),
}
_PRESET_WORDS = {
    "full": ("Full", "The paper's budget (200 particles x 15 iterations) and the local fit on finer silhouettes"),
    "preview": ("Preview", "A quick look at a take: 50 particles x 4 iterations and the local fit at the search's "
                           "resolution, several times faster (README, 'Speed')"),
}
_BACKEND_WORDS = {
    "auto": ("Auto", "The GPU (GLSL) on a hardware GPU, else the fast compiled CPU path, else NumPy; the GPU is "
                     "probed in a separate process first"),
    "numpy": ("NumPy", "Reference implementation: slow, always available"),
    "fast": ("Fast", "Compiled CPU rasteriser (numba)"),
    "gpu": ("GPU", "GLSL likelihood on the GPU through Blender's gpu module, an error where it cannot start (in "
                   "Blender, tracking then runs in the foreground: the GPU is reachable only from the main thread)"),
}
# The background models the tracker knows (Tracker._background_models: a plate, or one made from the clip by
# core/evidence/background.py's BackgroundModel.from_frames methods).
_BACKGROUND_WORDS = {
    "auto": ("Auto", "The capture's empty-scene plate (background/<camera>.png) where there is one, else the clip's "
                     "temporal median"),
    "plate": ("Plate", "The capture's background/<camera>.png for every camera (an error where one is missing)"),
    "median": ("Median", "Per-pixel temporal median of frames spread over the clip, exposure-matched"),
    "mog2": ("MOG2", "OpenCV's Gaussian-mixture estimate of the empty scene (weaker than the median on short "
                     "clips)"),
    "knn": ("KNN", "OpenCV's nearest-neighbour estimate of the empty scene (weaker than the median on short clips)"),
}
# core/evidence/learned.py's LANDMARK_MODEL_FILES, named here so that the panel need not load OpenCV to list them,
# and "auto": the preset's model (PRESETS)
_LANDMARK_WORDS = {
    "auto": ("Auto", "The preset's: Heavy for Full, Full for Preview (Heavy nearly doubles Preview's time)"),
    "full": ("Full", "BlazePose Full: about a fifth less time per frame than Heavy, nearly half for Preview"),
    "heavy": ("Heavy", "BlazePose Heavy: the Full preset's, better on every sample scene but two "
                       "(docs/defaults.md, \"landmarks\")"),
}
# The local fits the tracker knows (Tracker checks settings.refine against these two).
_REFINE_WORDS = {
    "icp": ("ICP", "After the search, fit the silhouette outlines locally: less jitter, about a second more per "
                   "frame"),
    "none": ("None", "The optimiser's estimate as it is (the paper's comparison)"),
}


def _fallback_likelihood(name):
    weights = LIKELIHOODS[name]
    terms = ", ".join(weights.active_terms())
    return name, f"Terms {terms}" + (" (silhouettes from the learned person mask)" if weights.mask == "learned" else "")


def _choices(values, words, fallback=lambda value: (value.upper(), value)):
    return tuple(Choice(v, *(words.get(v) or fallback(v))) for v in values)


def _default_preset():
    """The preset whose settings are TrackingSettings' own defaults."""
    return next(name for name, overrides in PRESETS.items() if not overrides)


def _build_options():
    d = TrackingSettings
    options = (
        Option("algorithm", "Algorithm", "Optimiser that searches each frame's pose", d.algorithm,
               _choices(available_optimizers(), _ALGORITHM_WORDS)),
        Option("likelihood", "Likelihood", "Image cues the pose is scored against", d.likelihood,
               _choices(tuple(LIKELIHOODS), _LIKELIHOOD_WORDS, _fallback_likelihood)),
        Option("preset", "Preset", "Speed against accuracy: Full for the final take, Preview for a quick look",
               _default_preset(), _choices(tuple(PRESETS), _PRESET_WORDS)),
        Option("particles", "Particles", "Pose hypotheses per iteration (the budget per frame is particles x "
                                         "iterations)", d.particles),
        Option("iterations", "Iterations", "Annealing iterations / layers per frame", d.iterations),
        Option("seed", "Seed", "Random seed: the same seed repeats the same result", d.seed),
        Option("refine", "Refine Locally", "Local fit of the silhouette outlines after the search", d.refine,
               _choices(("icp", "none"), _REFINE_WORDS)),
        Option("backend", "Backend", "How poses are rendered and compared with the images", d.backend,
               _choices(BACKENDS, _BACKEND_WORDS)),
        Option("background", "Background", "How the empty scene is known, for the background-subtraction "
                                           "silhouettes", d.background,
               _choices(tuple(_BACKGROUND_WORDS), _BACKGROUND_WORDS)),
        Option("landmarks", "Landmark Model", "The learned model that finds the body's landmarks in each view",
               "auto", _choices(tuple(_LANDMARK_WORDS), _LANDMARK_WORDS)),
    )
    return {o.name: o for o in options}


OPTIONS = _build_options()
CHOICE_NAMES = tuple(OPTIONS)  # what the panel and the command line each hand to settings_from_choices


def settings_from_choices(choices, **overrides):
    """TrackingSettings from the user's choices: a mapping or an object (the panel's scene.mocap, the command
    line's parsed arguments) holding every one of CHOICE_NAMES (an object lacking one is an AttributeError: a
    choice one side forgets must not fall back to a default unseen); a mapping may leave some out. The preset comes
    first and the other choices override it; a number left None keeps the preset's, and so does the landmark
    model "auto". `refine` may be the panel's checkbox (True: "icp"). `overrides` (None ignored) replace choices:
    the backend a run resolved "auto" to."""
    unknown = set(overrides) - set(CHOICE_NAMES)
    if unknown:
        raise TypeError(f"settings_from_choices: no choice named {', '.join(sorted(unknown))}")

    def get(name):
        if overrides.get(name) is not None:
            return overrides[name]
        return choices.get(name) if isinstance(choices, dict) else getattr(choices, name)

    values = {name: get(name) for name in CHOICE_NAMES}
    if isinstance(values["refine"], bool):
        values["refine"] = "icp" if values["refine"] else "none"
    if values["landmarks"] == "auto":
        values["landmarks"] = None  # the preset's model
    for name, value in values.items():
        if value is not None:
            OPTIONS[name].check(value)
    preset = values.pop("preset") or OPTIONS["preset"].default
    return TrackingSettings.preset(preset, **values)


__all__ = ["CHOICE_NAMES", "Choice", "OPTIONS", "Option", "OptionError", "settings_from_choices"]
