"""Lengths measured on the actor (a known height, a tape measure's forearm) in place of what the footage gave.

The calibration reads the height within 2 % in a studio (4 % short in a cluttered room) but some segments only
within 5-10 % (the forearm, the neck, the shoulder width: docs/actor-calibration.md), and a user who has
measured the actor knows better. A measured segment sets that segment's factor so the calibrated body has exactly
that length; a measured height scales the whole body first (every segment, the head, hands and girth alike). The
other segments keep the calibration's lengths; a measured spine, neck, thigh or shin changes the height
accordingly.
"""
from __future__ import annotations

import dataclasses

from ..errors import InputError
from .proportions import SEGMENTS, Proportions, scaled_body, segment_lengths

MEASURABLE = ("height",) + SEGMENTS
# A length outside these is a typo (centimetres for metres, say): metres, (shortest, longest)
HEIGHT_RANGE_M = (0.5, 2.5)     # as the rig check's "a person" (0.5-3 m), a little tighter
SEGMENT_RANGE_M = (0.02, 1.2)   # a foot's or a neck's few centimetres to a long spine
# How far the footage's calibration misses a segment: the RMS of calibrated / true - 1, per cent, over the actor
# scenes (tools/calibration_accuracy.py prints it), for those past the 3 % the other segments and the height keep.
# The summary names them, so a user knows which lengths are worth a tape measure (docs/defaults.md,
# "FOOTAGE_MISS_PERCENT").
FOOTAGE_MISS_PERCENT = {"neck": 5.1, "forearm": 5.1, "hip_width": 4.4, "foot": 4.3, "shoulder_width": 4.3,
                        "upper_arm": 3.3, "thigh": 3.0}


class MeasuredLengthError(InputError):
    """A measured length that cannot be used: unknown segment, not a number, not a length of a person."""


def checked_length(name, metres):
    """`metres` as a measured `name` (height or a segment), or a MeasuredLengthError saying it is no length of a
    person and which range is."""
    shortest, longest = HEIGHT_RANGE_M if name == "height" else SEGMENT_RANGE_M
    if not shortest <= metres <= longest:
        raise MeasuredLengthError(f"{metres:g} m is not a {name.replace('_', ' ')} of a person; give metres "
                                  f"({shortest:g}-{longest:g})")
    return float(metres)


def parse_measured(items):
    """{segment: metres} from strings like "forearm=0.245" (the --measured options); a one-line
    MeasuredLengthError naming the problem and the fix."""
    out = {}
    for item in items or ():
        name, sep, value = str(item).partition("=")
        name = name.strip().replace("-", "_").replace(" ", "_")
        if not sep or name not in MEASURABLE:
            raise MeasuredLengthError(f"--measured {item!r}: give SEGMENT=METRES with SEGMENT one of "
                                      f"{', '.join(MEASURABLE)} (for example forearm=0.245)")
        try:
            out[name] = checked_length(name, float(value))
        except ValueError as exc:  # not a number, or not a person's
            reason = exc if isinstance(exc, MeasuredLengthError) else f"{value!r} is not a number of metres"
            raise MeasuredLengthError(f"--measured {item!r}: {reason}") from None
    return out


def _keys_of(factors, segment):
    """The factor keys of `segment` in `factors`: the symmetric key, or both sided ones."""
    sided = [f"{side}_{segment}" for side in "lr" if f"{side}_{segment}" in factors]
    return sided or [segment]


def measured_proportions(subject, proportions, measured, iterations=12, tolerance=1e-9):
    """`proportions` of `subject` with the measured lengths ({segment or "height": metres}) applied: the height
    by a uniform scale, then each measured segment's factor (fixed-point, since the widths share bones with the
    spine: a few rounds, until every measured segment is within `tolerance`, relative)."""
    factors, overall = dict(proportions.factors), proportions.overall
    if "height" in measured:
        scale = measured["height"] / segment_lengths(scaled_body(subject, proportions))["height"]
        factors, overall = {k: v * scale for k, v in factors.items()}, overall * scale
    segments = {k: v for k, v in measured.items() if k != "height"}
    keys = {segment: _keys_of(factors, segment) for segment in segments}
    for _ in range(iterations if segments else 0):
        got = segment_lengths(scaled_body(subject, Proportions(factors, overall)))
        ratios = {key: segments[segment] / got[key] for segment in segments for key in keys[segment]}
        if all(abs(r - 1.0) <= tolerance for r in ratios.values()):
            break
        for key, ratio in ratios.items():
            factors[key] = factors.get(key, overall) * ratio
    return Proportions(factors, overall)


def with_measured(fit, subject, measured):
    """The ProportionsFit `fit` with the measured lengths applied and recorded (fit.measured); `fit` itself
    when nothing was measured, or None (a cancelled calibration)."""
    if not measured or fit is None:
        return fit
    proportions = measured_proportions(subject, fit.proportions, measured)
    return dataclasses.replace(fit, proportions=proportions,
                               lengths=segment_lengths(scaled_body(subject, proportions)), measured=dict(measured))
