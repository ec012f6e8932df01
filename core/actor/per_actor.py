"""Whose build each `track --actor` and `--calibrate-measured` gives: with one armature the option is that actor's;
with several (`--armature` repeated) each names its actor, `--actor Partner=FILE` and `--calibrate-measured
Partner:height=1.62` (docs/several-actors.md)."""
from pathlib import Path

from ..errors import InputError


def _split(item, separator, names, several, option, example):
    """(armature name, rest) of one option value; the name checked against `names` when several actors are
    tracked (and then required)."""
    name, sep, rest = str(item).partition(separator)
    if sep and name in names:
        return name, rest
    if several:
        raise InputError(f"{option} {item!r}: with several armatures say whose it is, as in {example} (armatures: "
                         f"{', '.join(names)})")
    return None, str(item)


def options_of(args, name):
    """(actor.json Path or None, ["SEGMENT=METRES", ...]) of the actor `name` from args.actor (a list of
    [ARMATURE=]FILE, or one path) and args.calibrate_measured ([ARMATURE:]SEGMENT=METRES); an InputError names an
    option that names no armature, or one actor given two saved calibrations."""
    names = [n for n in (getattr(args, "armature", None) or []) if n]
    several = len(names) > 1
    files = getattr(args, "actor", None)
    if files is not None and not isinstance(files, list):
        files = [files]
    mine = []
    for item in files or []:
        owner, path = _split(item, "=", names, several, "--actor", f"--actor {names[-1] if names else 'Lead'}="
                                                                     "OUT/actors/Lead/actor.json")
        if owner in (None, name) or not several:
            mine.append(Path(path))
    if len(mine) > 1:
        raise InputError(f"--actor: {len(mine)} saved calibrations for {name or 'the actor'}; give one")
    measured = []
    for item in getattr(args, "calibrate_measured", None) or []:
        owner, length = _split(item, ":", names, several, "--calibrate-measured",
                               f"--calibrate-measured {names[-1] if names else 'Lead'}:height=1.62")
        if owner in (None, name) or not several:
            measured.append(length)
    return (mine[0] if mine else None), measured
