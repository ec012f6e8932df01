"""Choose the actor's body: the user's rig as it is, or the calibration with its segments taken halfway and
its spine / thigh split and hip width read from the masks.

The landmark fit and the masks' refinement get the actor's height right to a per cent or two, but how that height
splits into segments only roughly: BlazePose's points carry the proportions it was trained on, so where the hip
joints sit between the shoulders and the knees is hardly measured: a short trunk on long legs (sample_scenes/actor3)
came out as a normal trunk on short legs and tracked worse than the rig. Each segment's deviation from a uniform
scale to the fitted height is then partly the actor's and partly an error of about the same size, so the body
tracked with takes half of it (the geometric mean of the calibration and the uniformly scaled rig, segment by
segment; head, hands and girth alike), which tracked better than the full calibration on every build it was
chosen on (docs/defaults.md, "halfway_body"). The spine and thighs, whose split the landmarks do not measure,
start from that uniform scale instead, and the masks set the split (core/actor/trunk_leg_split.py), then the hip
width (core/actor/hip_width_by_masks.py).

The person masks of the calibration frames then decide between the rig as it is and that body, each getting its
own poses: every frame refitted to the masks (and landmarks) by the tracker's local fit from the poses tracked
with the rig, then the XOR / model area of core/actor/silhouette_fit.SilhouetteCost; the least wins. They tell
a scaled body from the rig clearly, but not one scaled body from another: the full calibration, whose forearm
and hip width were searched against these same masks, looked best among them on two builds and tracked worst
there (docs/defaults.md, "compare_bodies").

In cluttered rooms with changing light the landmarks read the height 3-8 % short (actor9, actor12, lobby) and the
searches at that scale go wrong with it. The masks read the height better (core/actor/height_by_masks.py); where the two
disagree by more than the studio errors, the rig scaled uniformly to the masks' height stands in for the halfway
body. Where instead the two agree that the rig is the wrong height, the rig is not kept even when the masks like it
best: the masks' mismatch hardly changes with a few per cent of height in a cluttered room with three cameras.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .proportions import Proportions, scaled_body, segment_lengths

BODIES = ("rig", "halfway", "uniform")  # in this order, the first of equal mismatches wins
# Where the landmarks and the masks both read the actor's height more than this off the rig's, on the same side, the
# rig as it is is not the actor: each reads the height to about 1.5 % of the truth. The masks alone could not see a
# rig 3 % too tall (spin_dev: rig 0.1802, the rig at the masks' height 0.1801) and it tracked 4 mm worse
# (docs/defaults.md, "RIG_HEIGHT_GATE").
RIG_HEIGHT_GATE = 0.02


@dataclasses.dataclass
class BodyComparison:
    mismatch: dict  # body name -> mean XOR / model area over the calibration frames' views
    bodies: dict = dataclasses.field(default_factory=dict)  # body name -> Proportions
    # the searches by the masks: the trunk/leg split's, the hip width's and the height's
    # (core/actor/trunk_leg_split.py, core/actor/hip_width_by_masks.py, core/actor/height_by_masks.py)
    split: dict = dataclasses.field(default_factory=dict)
    hip_width: dict = dataclasses.field(default_factory=dict)
    height: dict = dataclasses.field(default_factory=dict)
    ruled_out: tuple = ()  # bodies the height readings rule out whatever their mismatch (rig_ruled_out)

    @property
    def chosen(self):
        left = [name for name in self.mismatch if name not in self.ruled_out]
        return min(left, key=lambda name: (self.mismatch[name], BODIES.index(name)))

    def as_dict(self):
        searches = {name: search for name, search in (("split", self.split), ("hip_width", self.hip_width),
                                                      ("height", self.height)) if search}
        ruled_out = {"ruled_out": list(self.ruled_out)} if self.ruled_out else {}
        return {"mismatch": dict(self.mismatch), "chosen": self.chosen, **ruled_out, **searches}


def rig_ruled_out(rig_height, height):
    """Whether the landmarks' and the masks' heights (`height`: height_by_masks' record) both lie more than
    RIG_HEIGHT_GATE from `rig_height` (m), on the same side."""
    off = np.array([height["landmark_height_m"], height["masks_height_m"]]) / rig_height - 1.0
    return bool(np.all(np.abs(off) > RIG_HEIGHT_GATE) and off[0] * off[1] > 0)


def fitted_scale(fit):
    """The uniform scale of the rig to the height of `fit` (a ProportionsFit)."""
    return fit.lengths["height"] / fit.subject_lengths["height"]


def halfway_body(fit):
    """Proportions halfway (geometric mean, segment by segment) between `fit` (a ProportionsFit) and the rig
    scaled uniformly to the fitted height."""
    scale = fitted_scale(fit)
    return Proportions({k: float(np.sqrt(f * scale)) for k, f in fit.proportions.factors.items()},
                       float(np.sqrt(fit.proportions.overall * scale)))


def uniform_body(fit, height):
    """The rig scaled uniformly (every segment, head, hands and girth) to `height` (m), in the fit's keys."""
    scale = height / fit.subject_lengths["height"]
    return Proportions({k: scale for k in fit.proportions.factors}, scale)


def candidate_bodies(fit):
    """name -> Proportions of the bodies the masks choose between, in the fit's segment keys."""
    return {"rig": Proportions({k: 1.0 for k in fit.proportions.factors}, 1.0), "halfway": halfway_body(fit)}


def compare_bodies(fit, subject, tracker, targets, rig_poses):
    """BodyComparison of the rig and the halfway body, its trunk/leg split and then its hip width set by the masks
    (core/actor/trunk_leg_split.py, core/actor/hip_width_by_masks.py), for `subject`'s tracked frames. Where the masks
    read that body's height more than core/actor/height_by_masks.GATE off the landmarks', the rig scaled uniformly to
    the masks' height stands in for it: in rooms where the landmarks misread the height (clutter, changing light) their
    segments' deviations are no better, and there that body tracked better than the halfway one scaled to it
    (docs/defaults.md, "compare_bodies"). targets: the CalibrationTargets of fit.frames
    (core/actor/silhouette_fit.calibration_targets, the ones the refinement used); rig_poses (F,D): those frames as
    tracked with the rig, every body's start (so no body starts closer to the masks)."""
    from .height_by_masks import height_by_masks
    from .hip_width_by_masks import hip_width_by_masks, widened
    from .trunk_leg_split import split_by_masks, traded

    known = {}  # the searches end on bodies they already scored (the height's grid centre is the body chosen)

    def mismatch(bodies):
        bodies = list(bodies)
        keys = [(tuple(sorted(p.factors.items())), p.overall) for p in bodies]
        new = {k: p for k, p in zip(keys, bodies) if k not in known}
        costs = mask_mismatch(subject, tracker.proxy, targets.cameras, targets.masks,
                              [(p, rig_poses) for p in new.values()], targets.keypoints, targets.resolution(tracker),
                              tracker.settings.backend, tracker.settings.landmarks)
        known.update(zip(new, costs))
        return [known[k] for k in keys]

    bodies = candidate_bodies(fit)
    halfway = bodies["halfway"]
    level = Proportions({**halfway.factors, **{k: fitted_scale(fit) for k in halfway.factors if k == "spine" or
                                                k.endswith("thigh")}}, halfway.overall)  # the usual split
    t, grid = split_by_masks(level, fit.subject_lengths, mismatch)
    split = traded(level, fit.subject_lengths, t)
    w, widths = hip_width_by_masks(split, mismatch)
    body = widened(split, w)
    height = height_by_masks(subject, body, mismatch)
    if height["taken"]:  # the landmarks misread the height, so their proportions are not trusted either
        del bodies["halfway"]
        bodies["uniform"] = uniform_body(fit, height["masks_height_m"])
    else:
        bodies["halfway"] = body
    comparison = BodyComparison(dict(zip(bodies, mismatch(bodies.values()))), bodies,
                                {"spine_log_change": t, "grid": grid}, {"log_change": w, "grid": widths}, height)
    if comparison.chosen == "rig" and rig_ruled_out(fit.subject_lengths["height"], height):
        if "uniform" not in bodies:  # the rig at the masks' height: what the masks could not tell from the rig
            bodies["uniform"] = uniform_body(fit, height["masks_height_m"])
            comparison.mismatch["uniform"] = mismatch([bodies["uniform"]])[0]
        comparison.ruled_out = ("rig",)
    return comparison


def mask_mismatch(subject, proxy, cameras, masks, candidates, keypoints=None, resolution=1.0, backend="auto",
                  landmarks="full"):
    """Per candidate (Proportions, start poses (F,D)): the mean XOR / model area of that body against the masks
    (per frame a list of one bool mask per camera, at the cameras' resolution), its poses first refitted to the
    masks (and keypoints, of the landmark model `landmarks`) from the start poses. resolution: the masks' scale over
    the tracker's energy scale."""
    from .silhouette_fit import SilhouetteCost, refit_poses, scaled_proxy

    costs = []
    for proportions, start in candidates:
        poses = refit_poses(*scaled_proxy(subject, proxy, proportions), cameras, masks, np.asarray(start, float),
                            keypoints, resolution, landmarks)
        costs.append(float(SilhouetteCost(subject, proxy, cameras, masks, poses, backend)([proportions])[0]))
    return costs


def keep_chosen(fit, subject, comparison):
    """`fit` with the chosen body's proportions and lengths, the comparison and the full calibration's factors
    and lengths recorded (for inspection, and to reuse the measurement)."""
    chosen = comparison.chosen
    record = {**(fit.silhouettes or {}), "body_check": {
        **comparison.as_dict(), "fitted_factors": dict(fit.proportions.factors),
        "fitted_overall": fit.proportions.overall, "fitted_lengths_m": dict(fit.lengths)}}
    proportions = (comparison.bodies or candidate_bodies(fit))[chosen]
    lengths = dict(fit.subject_lengths) if chosen == "rig" else segment_lengths(scaled_body(subject, proportions))
    return dataclasses.replace(fit, proportions=proportions, lengths=lengths, silhouettes=record)
