"""The actor calibration file (actor.json): the fitted proportions, saved with a result and reused for later
takes of the same actor. It keeps the segment lengths in metres as well as the factors, so a later take
tracked with another rig gets the actor's lengths, not the factors of a rig it does not use."""
from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from ..atomic_files import write_json
from .proportions import Proportions, ProportionsError, segment_lengths
from .landmark_fit import proportions_for_lengths

FORMAT = "markerless_mocap.actor"
VERSION = 1


class ActorFileError(InputError):
    """actor.json missing, unreadable, or not an actor calibration."""


def save_actor(path, fit, subject_name="", capture=""):
    """Write a ProportionsFit as actor.json (atomically)."""
    data = {"format": FORMAT, "version": VERSION, "subject": subject_name, "capture": str(capture),
            "frames": fit.frames, "symmetric": not any(k[:2] in ("l_", "r_") for k in fit.proportions.factors),
            "factors": fit.proportions.factors, "overall": fit.proportions.overall,
            "height_m": fit.lengths["height"], "lengths_m": fit.lengths, "subject_lengths_m": fit.subject_lengths,
            "landmark_rms_m": {"subject": fit.rms_before, "calibrated": fit.rms_after}}
    if fit.silhouettes is not None:
        data["silhouettes"] = fit.silhouettes
    if fit.measured:
        data["measured_m"] = fit.measured
    return write_actor(path, data)


def write_actor(path, data):
    """Write an actor calibration dict (as load_actor returns it) to `path`, atomically."""
    path = Path(path)
    write_json(path, data)
    return path


def load_actor(path):
    """The dict saved by save_actor, or a one-line ActorFileError naming the problem and the fix."""
    path = Path(path)
    if path.is_dir():
        path = path / "actor.json"
    if not path.is_file():
        raise ActorFileError(f"{path}: no actor calibration there; run `markerless_mocap calibrate ... --out DIR` "
                             "(or track --calibrate) and pass DIR/actor.json")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ActorFileError(f"{path}: not readable as JSON ({exc}); calibrate again to rewrite it") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ActorFileError(f"{path}: not an actor calibration (no \"format\": \"{FORMAT}\"); pass the actor.json "
                             "that `calibrate` wrote")
    if not isinstance(data.get("lengths_m"), dict) or not isinstance(data.get("factors"), dict):
        raise ActorFileError(f"{path}: the calibration has no segment lengths; calibrate again to rewrite it")
    return data


def actor_body(data, body):
    """`body` (the user's rig) with the calibrated actor's proportions: the body the tracker poses. A calibration that
    kept the rig gives `body` itself, so that the take is the one tracked without calibration to the last bit (a
    rebuilt copy differs by 1e-13 m, which the search's chaos grows to millimetres within 20-some frames)."""
    from .proportions import scaled_body

    proportions = proportions_for_body(data, body)
    return body if proportions.is_identity else scaled_body(body, proportions)


def proportions_for_body(data, body, tolerance=1e-6):
    """The Proportions that give `body` the calibrated actor: the saved factors when `body` is the rig the
    calibration was fitted on (same segment lengths), else factors that reproduce the saved lengths."""
    same_rig = False
    try:
        own = segment_lengths(body)
        same_rig = all(abs(own[k] - v) <= tolerance * max(1.0, abs(v)) for k, v in data["subject_lengths_m"].items()
                       if k in own)
        if same_rig:
            return Proportions(data["factors"], data["overall"])
        return proportions_for_lengths(body, data["lengths_m"])
    except (KeyError, TypeError, ProportionsError) as exc:
        # the rig it was fitted on with factors no person has: the file was edited or damaged, not the wrong rig
        what = "holds proportions no person has" if same_rig else "does not fit this rig"
        fix = "" if isinstance(exc, ProportionsError) else "; calibrate again with this rig"
        raise ActorFileError(f"the actor calibration {what} ({exc}){fix}") from None
