"""The takes of a batch: a TAKES.toml file of [[take]] tables, or a folder of capture folders.

    [defaults]                      tracking options for every take (the command line's names, underscores)
    [[take]]
    name = "walk01"                 names DIR/<name>/ (letters, digits, - _ .)
    scene = "subjects/anna.blend"   the subject; relative paths are relative to the TOML file's folder
    capture = "captures/walk01"
    frames = "0-599"                optional: "A-B" inclusive or [A, B]; default every frame
    armature = "Armature"           optional; a list (["Lead", "Partner"]) tracks several actors at once, in chunks
                                    as one actor's take (each chunk tracks them together, as `track` does)
    actor = "anna/actor.json"       optional: an actor calibration to track with
    calibrate = false               optional: track with the rig's proportions; by default a take of at least
                                    20 frames without `actor` (or whose actor was measured) is tracked with the
                                    actor's, fitted on its first frames
    measured = ["height=1.72"]      optional: lengths measured on the actor for that fit (several actors: say whose,
                                    "Partner:height=1.62")
    seed = 1                        optional: any tracking option, over [defaults]

Every mistake is an InputError naming the take (or the file) and the fix, found before anything is tracked. Whether
the subject holds a rig is checked where Blender's data can be read (operators/cmd_batch.py); the rest here.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from ..actor.actor_file import load_actor
from ..actor.measured_lengths import parse_measured
from ..actor.per_actor import options_of
from ..capture.calibration import find_calibration_file
from ..capture.capture import load_capture
from ..errors import InputError
from ..results.result_folder import actor_folder_name
from ..tracking.options import CHOICE_NAMES, settings_from_choices
from .chunk_folder import check_take_name

TAKE_KEYS = ("name", "scene", "capture", "frames", "armature", "actor", "calibrate", "measured")
SUBJECT_FILE = "subject.blend"  # a capture folder's own subject, when a batch is given a folder of captures


class TakeListError(InputError):
    """A take list that cannot be run; the message names the take and the fix."""


@dataclass
class Take:
    name: str
    scene: Path
    capture: Path
    frames: tuple  # (first, last) inclusive
    armature: str | None = None  # the one armature tracked (None: the scene's only one)
    actor: Path | None = None
    choices: dict = field(default_factory=dict)  # tracking options (CHOICE_NAMES) given for this take
    # fit the actor's proportions first (operators/cmd_batch.py; then `actor` is that fit): True, False, or None for
    # the default (fitted on a take long enough for it, as `track` does)
    calibrate: bool | None = None
    armatures: tuple = ()  # several actors tracked at once (then `armature` is None)
    measured: tuple = ()  # "[ARMATURE:]SEGMENT=METRES" for the actor fit, as `track --calibrate-measured` takes them
    fitted: dict = field(default_factory=dict)  # several actors: armature -> the actor.json the batch fitted

    @property
    def several(self):
        return len(self.armatures) > 1

    @property
    def names(self):
        """The armatures tracked: several, the one named, or [None] for the scene's only one."""
        return list(self.armatures) if self.several else [self.armature]

    @property
    def actor_folders(self):
        """Each actor's folder name under a result's actors/ (core/results/result_folder.py), or [None] for one
        actor, whose files are the result folder's own."""
        return [actor_folder_name(n) for n in self.names] if self.several else [None]

    def measured_of(self, name):
        """The SEGMENT=METRES lengths of actor `name` (None: the take's one actor), read from `measured` as `track
        --calibrate-measured` reads them (an InputError where several actors are tracked and one is not named)."""
        names = list(self.armatures) or ([self.armature] if self.armature else [])
        return options_of(SimpleNamespace(armature=names, calibrate_measured=list(self.measured)), name)[1]

    def settings(self):
        return settings_from_choices(self.choices)

    @property
    def n_frames(self):
        return self.frames[1] - self.frames[0] + 1


def _parse_frames(value, where):
    if isinstance(value, str):
        a, sep, b = value.partition("-")
        try:
            first, last = int(a), int(b) if sep else int(a)
        except ValueError:
            raise TakeListError(f"{where}: frames {value!r} must look like \"0-599\" (inclusive, from 0)") from None
    elif isinstance(value, list) and len(value) == 2 and all(isinstance(v, int) and not isinstance(v, bool)
                                                              for v in value):
        first, last = value
    else:
        raise TakeListError(f"{where}: frames {value!r} must be \"A-B\" or [A, B] (inclusive, from 0)")
    if first < 0:
        raise TakeListError(f"{where}: frames {first}-{last}: capture frames count from 0")
    if last < first:
        raise TakeListError(f"{where}: frames {first}-{last}: the last frame comes before the first")
    return first, last


def _choices(table, where):
    out = {}
    for name in CHOICE_NAMES:
        if name in table:
            out[name] = table[name]
    try:
        settings_from_choices(out)
    except (InputError, TypeError, ValueError) as exc:
        raise TakeListError(f"{where}: {exc}") from None
    return out


def _path(value, base, where, key):
    if not isinstance(value, str) or not value:
        raise TakeListError(f"{where}: {key} must be a path (text), got {value!r}")
    path = Path(value).expanduser()
    return path if path.is_absolute() else base / path


def _check_capture(take, where):
    """The capture's frame count, the take's frames within it (a missing or broken capture: its reason)."""
    try:
        capture = load_capture(take.capture)
    except (InputError, OSError) as exc:
        raise TakeListError(f"{where}: capture {take.capture}: {exc}") from None
    try:
        n = capture.frames.n_frames
    finally:
        capture.close()
    if take.frames is None:
        take.frames = (0, n - 1)
    elif take.frames[1] >= n:
        raise TakeListError(f"{where}: frames {take.frames[0]}-{take.frames[1]}, but capture {take.capture} has "
                            f"{n} frames (0-{n - 1})")
    return take


def _check_files(take, where):
    if not take.scene.is_file():
        raise TakeListError(f"{where}: scene {take.scene}: no such file (the subject .blend)")
    if take.actor is not None:
        try:
            load_actor(take.actor)
        except (InputError, OSError) as exc:
            raise TakeListError(f"{where}: actor: {exc}") from None


def _check_overlaps(takes):
    """Two takes of one capture whose frames overlap would track the same frames twice under two names."""
    by_capture = {}
    for take in takes:
        by_capture.setdefault(take.capture.resolve(), []).append(take)
    for same in by_capture.values():
        same.sort(key=lambda t: t.frames)
        for a, b in zip(same, same[1:]):
            if b.frames[0] <= a.frames[1]:
                raise TakeListError(f"take {b.name!r}: frames {b.frames[0]}-{b.frames[1]} overlap take {a.name!r} "
                                    f"({a.frames[0]}-{a.frames[1]}) of the same capture {a.capture}; give each "
                                    "frame to one take")


def read_take_list(path, defaults=None, scene=None, armature=None):
    """The takes of a TAKES.toml file or a folder of capture folders, checked. `defaults`: tracking options from
    the command line (below the file's [defaults]); `scene`: the subject for captures without their own;
    `armature`: a name or a list of names (several actors) for the takes that do not name theirs."""
    path = Path(path)
    defaults = {k: v for k, v in (defaults or {}).items() if v is not None}
    if path.is_dir():
        takes = _takes_of_folder(path, defaults, scene)
    elif path.is_file():
        takes = _takes_of_file(path, defaults, scene)
    else:
        raise TakeListError(f"{path}: no such take list (a TAKES.toml file or a folder of capture folders)")
    if not takes:
        raise TakeListError(f"{path}: no takes in it ([[take]] tables, or capture folders with a calibration)")
    if armature:
        for take in takes:
            if take.armature is None and not take.armatures:
                take.armature, take.armatures = _armatures(armature, f"take {take.name!r}: --armature")
    for take in takes:
        where = f"take {take.name!r}"
        _check_files(take, where)
        _check_capture(take, where)
        _check_measured(take, where)
    _check_overlaps(takes)
    return takes


def _takes_of_file(path, defaults, scene):
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise TakeListError(f"{path}: cannot be read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise TakeListError(f"{path}: not valid TOML ({exc})") from None
    unknown = set(data) - {"take", "defaults"}
    if unknown:
        raise TakeListError(f"{path}: unknown {', '.join(sorted(unknown))} (the file holds [[take]] tables and "
                            "an optional [defaults] table)")
    table = data.get("defaults", {})
    if not isinstance(table, dict):
        raise TakeListError(f"{path}: defaults must be a table ([defaults])")
    bad = set(table) - set(CHOICE_NAMES)
    if bad:
        raise TakeListError(f"{path}: [defaults]: unknown {', '.join(sorted(bad))} (tracking options are "
                            f"{', '.join(CHOICE_NAMES)})")
    defaults = {**defaults, **_choices(table, f"{path}: [defaults]")}
    entries = data.get("take", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise TakeListError(f"{path}: takes must be [[take]] tables")
    base, takes, seen = path.parent, [], set()
    for number, entry in enumerate(entries, 1):
        name = entry.get("name")
        where = f"take {name!r}" if isinstance(name, str) else f"{path}: take number {number}"
        if name is None:
            raise TakeListError(f"{where}: needs a name")
        try:
            check_take_name(name)
        except InputError as exc:
            raise TakeListError(f"{where}: {exc}") from None
        if name in seen:
            raise TakeListError(f"{where}: a second take of that name (each names its own result folder)")
        seen.add(name)
        unknown = set(entry) - set(TAKE_KEYS) - set(CHOICE_NAMES)
        if unknown:
            raise TakeListError(f"{where}: unknown key {', '.join(sorted(unknown))} (a take has "
                                f"{', '.join(TAKE_KEYS)} and the tracking options {', '.join(CHOICE_NAMES)})")
        for key in ("capture",) + (() if scene is not None else ("scene",)):
            if key not in entry:
                raise TakeListError(f"{where}: needs a {key}")
        armature, armatures = _armatures(entry.get("armature"), where)
        if armatures and "actor" in entry:
            raise TakeListError(f"{where}: actor is one actor's calibration, but the take tracks "
                                f"{', '.join(armatures)}: leave actor out (each actor's build is fitted on the take)")
        calibrate = entry.get("calibrate")
        if calibrate is not None and not isinstance(calibrate, bool):
            raise TakeListError(f"{where}: calibrate must be true or false")
        if calibrate and "actor" in entry:
            raise TakeListError(f"{where}: calibrate and actor both given: calibrate fits a new actor.json, actor "
                                "reuses one; keep one of them")
        measured = _measured(entry, where)
        takes.append(Take(
            name, _path(entry["scene"], base, where, "scene") if "scene" in entry else Path(scene),
            _path(entry["capture"], base, where, "capture"),
            _parse_frames(entry["frames"], where) if "frames" in entry else None, armature,
            _path(entry["actor"], base, where, "actor") if "actor" in entry else None,
            {**defaults, **_choices(entry, where)}, calibrate, armatures, measured))
    return takes


def _measured(entry, where):
    """A take's `measured` lengths (texts; read per actor by _check_measured), refused where no actor is fitted
    (`actor` given, or `calibrate = false`)."""
    items = entry.get("measured")
    if items is None:
        return ()
    if not isinstance(items, list) or not all(isinstance(i, str) for i in items):
        raise TakeListError(f"{where}: measured must be a list of \"SEGMENT=METRES\" texts, as [\"height=1.72\"]")
    if items and ("actor" in entry or entry.get("calibrate") is False):
        raise TakeListError(f"{where}: measured lengths are for fitting the actor, but the take "
                            f"{'reuses actor' if 'actor' in entry else 'has calibrate = false'}: leave one out")
    return tuple(items)


def _check_measured(take, where):
    """The take's measured lengths read as `track --calibrate-measured` reads them, each actor's named when the take
    has several (its armatures known by now, the command line's --armature included)."""
    try:
        for name in take.names:
            parse_measured(take.measured_of(name))
    except InputError as exc:
        raise TakeListError(f"{where}: measured: {exc}") from None


def _armatures(value, where):
    """(armature, armatures) of a take's `armature`: a name, or a list of names (several actors, each once)."""
    if value is None or isinstance(value, str):
        return value, ()
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise TakeListError(f"{where}: armature must be the armature object's name (text), or a list of names for "
                            "several actors")
    if len(set(value)) != len(value):
        raise TakeListError(f"{where}: armature {value}: a name given twice (name each actor's armature once)")
    return (value[0], ()) if len(value) == 1 else (None, tuple(value))


def _is_capture(folder):
    try:
        find_calibration_file(folder)
    except (InputError, OSError):
        return False
    return (folder / "videos").is_dir()


def _takes_of_folder(folder, defaults, scene):
    takes = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")):
        if not _is_capture(sub):
            continue
        where = f"take {sub.name!r} ({sub})"
        try:
            check_take_name(sub.name)
        except InputError as exc:
            raise TakeListError(f"{where}: {exc}; rename the folder or list the takes in a TAKES.toml") from None
        own = sub / SUBJECT_FILE
        if not own.is_file() and scene is None:
            raise TakeListError(f"{where}: no {SUBJECT_FILE} in it; put the subject there or give --scene")
        takes.append(Take(sub.name, own if own.is_file() else Path(scene), sub, None, None, None, dict(defaults)))
    return takes


__all__ = ["SUBJECT_FILE", "TAKE_KEYS", "Take", "TakeListError", "read_take_list"]
