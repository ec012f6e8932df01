"""The tracker's checkpoint: what `--resume` needs to continue exactly where a run stopped, as plain, versioned
data. No pickled classes, so a renamed class or a new release can still read it.

    checkpoint.npz   one file, replaced in one step (a kill never leaves one frame's arrays beside another's
                     description):
        meta          JSON text: {"format": FORMAT, "settings": {...}, "state": tree}; the tree holds the
                      tracker's state (Tracker.state()) with each array replaced by {"$array": its name}
        estimates.*   the solved frames (FrameEstimate's fields), stacked over the frames
        state.N       the state's arrays

Before this format the checkpoint was checkpoint.pkl (pickled FrameEstimates and optimiser objects); read_legacy
reads one with the classes where they live now and converts it.
"""
import importlib
import json
import pickle
import zipfile

import numpy as np

from ..errors import InputError
from .settings import FrameEstimate

FORMAT = 1
FILE_NAME = "checkpoint.npz"
LEGACY_FILE_NAME = "checkpoint.pkl"
_ARRAY = "$array"  # the key of an array's place in meta's tree


class CheckpointError(InputError):
    """A checkpoint that cannot be resumed (unreadable, from a newer release, other settings); the message names the
    file and the fix."""


# ---------------------------------------------------------------- the optimiser's part of the state
def optimizer_state(optimizer):
    """The optimiser's state as plain data: its name, the arrays it carries and its random generator's state."""
    return {"name": optimizer.name, "arrays": optimizer.state_arrays(), "random": optimizer.random_state()}


def restore_optimizer(optimizer, state):
    """Put optimizer_state()'s data back into `optimizer` (built with the same settings)."""
    if state["name"] != optimizer.name:
        raise CheckpointError(f"the checkpoint holds the state of optimiser {state['name']!r}, not of "
                              f"{optimizer.name!r}: resume with the same options, or track again without --resume")
    optimizer.restore(state["arrays"], state["random"])


# ---------------------------------------------------------------- plain data <-> arrays and JSON
def _plain(value, arrays, where):
    """`value` as a JSON tree; its arrays go into `arrays` (state.N) and leave {"$array": "state.N"} in the tree."""
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            raise TypeError(f"checkpoint state {where}: an array of Python objects cannot be stored as plain data")
        name = f"state.{len(arrays)}"
        arrays[name] = value
        return {_ARRAY: name}
    if isinstance(value, dict):
        bad = [k for k in value if not isinstance(k, str)]
        if bad:
            raise TypeError(f"checkpoint state {where}: keys must be strings, got {bad!r}")
        return {k: _plain(v, arrays, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, arrays, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"checkpoint state {where}: a {type(value).__name__} is not plain data (the checkpoint stores "
                    "arrays, numbers, strings, lists and dicts of them)")


def _unplain(tree, arrays):
    if isinstance(tree, dict):
        if set(tree) == {_ARRAY}:
            return arrays[tree[_ARRAY]]
        return {k: _unplain(v, arrays) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_unplain(v, arrays) for v in tree]
    return tree


def _estimate_arrays(estimates):
    def values(name, default=None):
        return [getattr(e, name, default) for e in estimates]

    cpu = [np.nan if v is None else v for v in values("cpu_seconds")]
    arrays = {"estimates.frame": np.array(values("frame"), dtype=np.int64),
              "estimates.pose": np.stack(values("pose")), "estimates.joints": np.stack(values("joints")),
              "estimates.energy": np.array(values("energy"), dtype=np.float64),
              "estimates.seconds": np.array(values("seconds"), dtype=np.float64),
              "estimates.evaluations": np.array(values("evaluations"), dtype=np.int64),
              "estimates.cpu_seconds": np.array(cpu, dtype=np.float64)}
    seen = [i for i, v in enumerate(values("landmarks")) if v is not None]
    if seen:  # the frames solved with learned evidence (all of a run's, or none)
        arrays["estimates.landmarks_of"] = np.array(seen, dtype=np.int64)
        arrays["estimates.landmarks"] = np.stack([estimates[i].landmarks for i in seen])
        arrays["estimates.landmark_visibility"] = np.stack([estimates[i].landmark_visibility for i in seen])
    return arrays


def _estimates(arrays):
    frames = arrays["estimates.frame"]
    landmarks = {}
    if "estimates.landmarks_of" in arrays:
        for k, i in enumerate(arrays["estimates.landmarks_of"]):
            landmarks[int(i)] = (arrays["estimates.landmarks"][k], arrays["estimates.landmark_visibility"][k])
    out = []
    for i, frame in enumerate(frames):
        cpu = float(arrays["estimates.cpu_seconds"][i])
        uv, visibility = landmarks.get(i, (None, None))
        out.append(FrameEstimate(int(frame), arrays["estimates.pose"][i], arrays["estimates.joints"][i],
                                 float(arrays["estimates.energy"][i]), float(arrays["estimates.seconds"][i]),
                                 int(arrays["estimates.evaluations"][i]), landmarks=uv, landmark_visibility=visibility,
                                 cpu_seconds=None if np.isnan(cpu) else cpu))
    return out


# Settings added after checkpoints were first written, with what a checkpoint written before them was tracked with:
# None, any value (it resumes with this run's; the tracker's state for it is rebuilt from the next frames,
# Tracker.restore); else that value (a run before the heavy landmark model looked with the full one).
ADDED_SETTINGS = {"check_clothes": None, "landmarks": "full"}


def plain_settings(settings_dict):
    """Settings as they read back from JSON (tuples become lists), so the two sides of a comparison agree."""
    return json.loads(json.dumps(settings_dict))


def setting_differences(saved, current):
    """{name: (the checkpoint's value, this run's)} of the settings in which a checkpoint's run (`saved`) differs
    from this run (`current`, both dicts), a setting added since the checkpoint was written taken as ADDED_SETTINGS
    says; a setting one side lacks is None there."""
    saved, current = plain_settings(saved), plain_settings(current)
    for name, before in ADDED_SETTINGS.items():
        if name not in saved and name in current:
            saved[name] = current[name] if before is None else before
    return {name: (saved.get(name), current.get(name)) for name in sorted(set(saved) | set(current))
            if saved.get(name) != current.get(name)}


def same_settings(saved, current):
    """Whether a checkpoint's settings (`saved`) are the run's (`current`): setting_differences finds none."""
    return not setting_differences(saved, current)


def write(fh, estimates, state, settings_dict):
    """Write a checkpoint of `estimates` (FrameEstimates), the tracker's `state` (plain data: Tracker.state()) and
    the run's settings (TrackingSettings.to_dict()) to the open binary file `fh`."""
    arrays = {}
    tree = _plain(state, arrays, "state")
    meta = {"format": FORMAT, "settings": plain_settings(settings_dict), "state": tree}
    np.savez(fh, meta=np.array(json.dumps(meta)), **_estimate_arrays(estimates), **arrays)


def read(path):
    """(estimates, state, settings dict) of the checkpoint file `path`, or a CheckpointError naming it."""
    unreadable = (OSError, ValueError, KeyError, IndexError, TypeError, EOFError, zipfile.BadZipFile)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        meta = json.loads(str(arrays.pop("meta")[()]))
        version = meta["format"]
    except unreadable as exc:
        raise _unreadable(path, exc) from None
    if not isinstance(version, int) or version < 1:
        raise _unreadable(path, f"format {version!r}")
    if version > FORMAT:
        raise CheckpointError(f"{path} was written by a newer release of Markerless Mocap (checkpoint format "
                              f"{version}; this release reads format {FORMAT}): resume it with that release or a "
                              "newer one, or track again without --resume")
    try:
        return _estimates(arrays), _unplain(meta["state"], arrays), meta["settings"]
    except unreadable as exc:
        raise _unreadable(path, exc) from None


def _unreadable(path, why):
    return CheckpointError(f"{path} cannot be read as a checkpoint ({why}); track again without --resume, or "
                           "choose another result folder")


# ---------------------------------------------------------------- checkpoint.pkl, before this format
# Where the modules an old pickle names live now that core/ is grouped into packages: old -> new, under core.
# A module not listed kept its place.
MOVED_MODULES = {
    "tracking": ("tracking.settings", "tracking.tracker"), "results": ("results.result_folder",),
    "limb_search": ("tracking.limb_search",), "motion_library": ("tracking.motion_library",),
    "smoothing": ("tracking.smoothing",), "evaluation": ("results.evaluation",), "overlay": ("results.overlay",),
    "body": ("body.model",), "proxy": ("body.proxy",), "rotations": ("body.rotations",),
    "rig_presets": ("body.rig_presets",), "rig_checks": ("body.rig_checks",), "pose_fitting": ("body.pose_fit",),
    "fast_kinematics": ("body.kinematics_fast",), "fast_skinning": ("body.skinning_fast",),
    "camera": ("capture.camera",), "likelihood": ("energy.likelihood",), "prior": ("energy.prior",),
    "keypoints": ("evidence.keypoints",), "fast_keypoints": ("evidence.keypoints_fast",),
    "keypoint_fit": ("evidence.keypoint_fit",), "evidence_crops": ("evidence.crops",),
    "evidence_agreement": ("evidence.agreement",), "view_presence": ("evidence.view_presence",),
    "features": ("evidence",), "motion_to_dof": ("mocap.to_dof",), "fast_jacobian": ("optimizers.jacobian_fast",),
    "actor_file": ("actor.actor_file",), "calibration_check": ("actor.body_choice",),
    "proportions": ("actor.proportions",), "proportions_fit": ("actor.landmark_fit",),
    "proportions_silhouette": ("actor.silhouette_fit",), "height_by_masks": ("actor.height_by_masks",),
    "hip_width_by_masks": ("actor.hip_width_by_masks",), "trunk_leg_split": ("actor.trunk_leg_split",),
    "measured_lengths": ("actor.measured_lengths",), "mask_line_search": ("actor.mask_line_search",),
}
MOVED_MODULES.update({f"features.{m}": (f"evidence.{m}",) for m in (
    "background", "diffusion", "errors", "exposure", "learned", "mask_cleanup", "view_features")})
_CORE = __name__.rsplit(".", 2)[0]  # this package's core, however the package is installed
_OTHER_MODULES = ("numpy", "builtins", "copyreg", "collections")


def _current_modules(module):
    """The modules that may hold what an old pickle calls `module` now, or None when it is not the add-on's."""
    head, sep, rest = module.partition(".core")
    if not sep or head.rpartition(".")[2] != "markerless_mocap" or (rest and not rest.startswith(".")):
        return None
    rest = rest.lstrip(".")
    return [f"{_CORE}.{m}" if m else _CORE for m in MOVED_MODULES.get(rest, (rest,))]


class _LegacyUnpickler(pickle.Unpickler):
    def __init__(self, fh, path):
        super().__init__(fh)
        self.path = path

    def find_class(self, module, name):
        candidates = _current_modules(module)
        if candidates is None:
            if module.split(".")[0] in _OTHER_MODULES:
                return super().find_class(module, name)
            raise CheckpointError(f"{self.path} names {module}.{name}, which no checkpoint of Markerless Mocap "
                                  "holds: it was not written by it; track again without --resume")
        for candidate in candidates:
            try:
                return getattr(importlib.import_module(candidate), name)
            except (ImportError, AttributeError):
                continue
        raise CheckpointError(f"{self.path} holds a {module}.{name}, which this release no longer has: track again "
                              "without --resume")


def read_legacy(path):
    """(estimates, state, settings dict) of a checkpoint.pkl, converted to this format's plain data."""
    try:
        with open(path, "rb") as fh:
            data = _LegacyUnpickler(fh, path).load()
        old = data["state"]
        estimates = [FrameEstimate(int(e.frame), e.pose, e.joints, float(e.energy), float(e.seconds),
                                   int(e.evaluations), landmarks=getattr(e, "landmarks", None),
                                   landmark_visibility=getattr(e, "landmark_visibility", None),
                                   cpu_seconds=getattr(e, "cpu_seconds", None)) for e in data["estimates"]]
        state = {"optimizer": optimizer_state(old["optimizer"]), "anchor": old["anchor"],
                 "history": list(old["history"]), "color_model": list(old["color_model"]),
                 "reference": list(old["reference"]), "limb_off_frames": dict(old.get("limb_off_frames", {})),
                 "next_guide": old.get("next_guide")}
        settings = data["settings"]
    except CheckpointError:
        raise
    except (OSError, EOFError, pickle.UnpicklingError, KeyError, IndexError, AttributeError, TypeError,
            ValueError) as exc:
        raise _unreadable(path, exc) from None
    return estimates, state, settings
