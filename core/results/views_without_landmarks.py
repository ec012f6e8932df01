"""What the user is told at the end of a take about the views whose landmarks were left out: report.json's
`views_shared` (frame -> cameras whose landmarks mostly disagreed with the other views and were all dropped,
core/evidence/landmark_consensus.py), as frame spans per camera, with what to do about it.

Such a view is most often one where someone else stands in front of the actor (the landmark model then returns
that person), sometimes one where the actor hides its own limbs; either way the user learns which stretch of the
take rests on fewer views.
"""
import json
from pathlib import Path

from ..tracking.frame_runs import consecutive_runs

# A camera is named only when its landmarks were left out on at least this many frames [DESIGN]: the agreement
# rule drops a whole view on a few frames of most takes with nobody else there (dusk and lobby: 1-4 of 60-100),
# on 10-12 of sit's 100 (the seated actor hiding its arms) and 5-37 of crossing_dev's 60 while the passer-by is in
# front (docs/how-it-tracks.md, "Other people in the room").
MIN_FRAMES = 5


def frame_spans(frames):
    """Frame numbers -> [(first, last)] of their runs of consecutive frames."""
    frames = sorted(int(f) for f in frames)
    return [(frames[a], frames[b - 1]) for a, b in consecutive_runs(frames)]


def views_without_landmarks(views_shared, min_frames=MIN_FRAMES):
    """{camera: [(first, last), ...]} of the cameras whose landmarks were left out on at least `min_frames`
    frames; `views_shared` as report.json has it ({frame (str or int): [camera names]})."""
    per_camera = {}
    for frame, names in views_shared.items():
        for name in names:
            per_camera.setdefault(name, []).append(int(frame))
    return {name: frame_spans(frames) for name, frames in sorted(per_camera.items()) if len(frames) >= min_frames}


def _spans_text(spans):
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in spans)


def views_without_landmarks_message(report, actors=1):
    """The end-of-take line about the views left out, or None when there is nothing to say. `report`: the take's
    report.json as a dict; with several actors tracked (`actors` > 1) the other actors are expected there."""
    left = views_without_landmarks(report.get("views_shared") or {})
    if not left:
        return None
    where = "; ".join(f"{name} on frames {_spans_text(spans)}" for name, spans in left.items())
    message = (f"landmarks left out: {where} (report.json, views_shared). Those frames rest on the other views: "
               "someone stood in front of the actor there, or the actor hid its own limbs from that camera.")
    if actors == 1:
        message += (" If another person walks through, place an armature on them too and track both "
                    "(--armature ACTOR --armature OTHER, or Track Every Armature in the Subject panel): their body "
                    "then keeps out of the actor's.")
    return message


def views_without_landmarks_in_result(folder):
    """The line for a finished result folder (its report.json), or None when there is nothing to say or no report
    to read (a batch's stitched take, read back by `batch` and the Track panel)."""
    try:
        report = json.loads((Path(folder) / "report.json").read_text())
    except (OSError, ValueError):
        return None
    return views_without_landmarks_message(report)
