"""Several actors in one frame loop: each actor's tracker solves the frame with the others' bodies set apart
(core/tracking/other_actors.py) at their poses of this frame: the ones solved before it this frame, the others
predicted (constant velocity from their last two frames) until they are solved."""
import numpy as np

from .observation import carried_on
from .other_actors import OtherActor, OtherActors


def pose_for_frame(tracker, frame):
    """`tracker`'s absolute pose at `frame`: solved, else predicted from its last frames; None before its first."""
    if tracker.estimates and tracker.estimates[-1].frame == int(frame):
        return np.asarray(tracker.estimates[-1].pose, dtype=np.float64)
    if not tracker.history:
        return None
    return carried_on(tracker._last_absolute(2), (1,))[-1]


def others_of(trackers, i, frame):
    """The OtherActors tracker `i` sees at `frame` (None when no other has a pose yet)."""
    actors = []
    for j, tracker in enumerate(trackers):
        pose = None if j == i else pose_for_frame(tracker, frame)
        if pose is not None:
            actors.append(OtherActor(tracker.body, tracker.proxy, pose, tracker.energy.rig_points))
    return OtherActors(actors) if actors else None
