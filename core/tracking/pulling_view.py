"""The view that pulled a refused estimate away: when the root gate (root_gate.py) refuses a solution, something in
the images drew the model off its person, most often another person crossing in front of it in one view. Each view
in play is scored alone (its image terms and its landmarks) on the refused estimate and on the prediction; the
view that favours the refused estimate most is left out of that frame's re-search, so the evidence that cannot be
split there counts less instead of pulling the model across.
Figures: docs/measurements.md, "Other people in the room"."""
import dataclasses

import numpy as np

# Fewer views than this left in play and none is left out: two views still triangulate, one does not.
MIN_VIEWS_TO_LEAVE_ONE_OUT = 3


def view_gains(energy, energy_fn, in_play, refused, predicted):
    """Per camera, how much lower the refused estimate's energy is than the prediction's with only that view's
    image terms and landmarks counting ((C,); nan for a view not in play). `energy`: the tracker's EnergyModel,
    left as it came; `energy_fn`: relative poses (P,D) -> (P,)."""
    in_play = np.asarray(in_play, dtype=bool)
    weights_before, keypoints = energy.view_weights, energy.keypoints
    gains = np.full(len(in_play), np.nan)
    pair = np.stack([np.asarray(refused, dtype=np.float64), np.asarray(predicted, dtype=np.float64)])
    try:
        for view in np.flatnonzero(in_play):
            alone = np.zeros(len(in_play))
            alone[view] = 1.0
            energy.set_view_weights(alone)
            if keypoints is not None:
                energy.keypoints = only_views(keypoints, alone > 0)
            scores = np.asarray(energy_fn(pair), dtype=np.float64)
            gains[view] = scores[1] - scores[0]
    finally:
        energy.view_weights, energy.keypoints = weights_before, keypoints
    return gains


def only_views(keypoints, keep):
    """The landmarks (KeypointTargets) with every view outside `keep` (C,) weighted 0."""
    return dataclasses.replace(keypoints, weight=keypoints.weight * np.asarray(keep, dtype=np.float64)[:, None])


def pulling_view(gains):
    """The view to leave out given view_gains(), or None: the one that favours the refused estimate most, when it
    does favour it and enough views stay in play."""
    gains = np.asarray(gains, dtype=np.float64)
    in_play = np.isfinite(gains)
    if in_play.sum() < MIN_VIEWS_TO_LEAVE_ONE_OUT:
        return None
    view = int(np.nanargmax(gains))
    return view if gains[view] > 0 else None
