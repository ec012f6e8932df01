"""Choose the actor's body: the user's rig as it is, or the calibration with its segments taken halfway.

The landmark fit and the masks' refinement get the actor's height right to a per cent or two, but how that height
splits into segments only roughly: BlazePose's points carry the proportions it was trained on, so where the hip
joints sit between the shoulders and the knees is hardly measured (the fitted spine / thigh ratio on eleven
scenes: 1.00-1.13 of the rig's whatever the truth, 0.92-1.13; README, "Actor calibration"). A short trunk on long legs
(sample_scenes/actor3) came out as a normal trunk on short legs (spine +9 %, thigh -12 %), and tracking with it
was worse than with the rig (18.4 -> 21.0 mm). Each segment's deviation from a uniform scale to the fitted height
is then partly the actor's and partly an error of about the same size, so the body tracked with takes half of it
(the geometric mean of the calibration and the uniformly scaled rig, segment by segment; head, hands and girth
alike). Tracking error (mm, seed 0) with the uniform scale / halfway / the full calibration: actor2 32.5 / 29.4 /
31.4, actor3 16.4 / 18.2 / 21.0, actor4 18.3 / 18.0 / 18.9, actor5 18.6 / 18.3 / 19.3.

The person masks of the calibration frames then decide between the rig as it is and that body, each getting its
own poses: every frame refitted to the masks (and landmarks) by the tracker's local fit from the poses tracked
with the rig, then the XOR / model area of core/proportions_silhouette.SilhouetteCost; the least wins. They tell
a scaled body from the rig clearly (actor2 0.239 against 0.165, actor5 0.261 / 0.144; walk, whose actor is the
rig, 0.132 / 0.138; actor6, where the fit missed the height by 2.5 %, 0.135 / 0.172), but not one scaled body
from another: the full calibration, whose forearm and hip width were searched against these same masks, looked
best among them on actor4 and actor5 and tracked worst there.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .proportions import Proportions, scaled_body, segment_lengths

BODIES = ("rig", "halfway")  # in this order, the first of equal mismatches wins


@dataclasses.dataclass
class BodyComparison:
    mismatch: dict  # body name -> mean XOR / model area over the calibration frames' views

    @property
    def chosen(self):
        return min(self.mismatch, key=lambda name: (self.mismatch[name], BODIES.index(name)))

    def as_dict(self):
        return {"mismatch": dict(self.mismatch), "chosen": self.chosen}


def halfway_body(fit):
    """Proportions halfway (geometric mean, segment by segment) between `fit` (a ProportionsFit) and the rig
    scaled uniformly to the fitted height."""
    scale = fit.lengths["height"] / fit.subject_lengths["height"]
    return Proportions({k: float(np.sqrt(f * scale)) for k, f in fit.proportions.factors.items()},
                       float(np.sqrt(fit.proportions.overall * scale)))


def candidate_bodies(fit):
    """name -> Proportions of the bodies the masks choose between, in the fit's segment keys."""
    return {"rig": Proportions({k: 1.0 for k in fit.proportions.factors}, 1.0), "halfway": halfway_body(fit)}


def compare_bodies(fit, subject, tracker, targets, rig_poses):
    """BodyComparison of candidate_bodies(fit) for `subject`'s tracked frames. targets: the CalibrationTargets
    of fit.frames (core/proportions_silhouette.calibration_targets, the ones the refinement used); rig_poses
    (F,D): those frames as tracked with the rig, every body's start (so no body starts closer to the masks)."""
    bodies = candidate_bodies(fit)
    costs = mask_mismatch(subject, tracker.proxy, targets.cameras, targets.masks,
                          [(p, rig_poses) for p in bodies.values()], targets.keypoints,
                          targets.resolution(tracker), tracker.settings.backend)
    return BodyComparison(dict(zip(bodies, costs)))


def mask_mismatch(subject, proxy, cameras, masks, candidates, keypoints=None, resolution=1.0, backend="auto"):
    """Per candidate (Proportions, start poses (F,D)): the mean XOR / model area of that body against the masks
    (per frame a list of one bool mask per camera, at the cameras' resolution), its poses first refitted to the
    masks (and keypoints) from the start poses. resolution: the masks' scale over the tracker's energy scale."""
    from .proportions_silhouette import SilhouetteCost, refit_poses, scaled_proxy

    costs = []
    for proportions, start in candidates:
        poses = refit_poses(*scaled_proxy(subject, proxy, proportions), cameras, masks, np.asarray(start, float),
                            keypoints, resolution)
        costs.append(float(SilhouetteCost(subject, proxy, cameras, masks, poses, backend)([proportions])[0]))
    return costs


def keep_chosen(fit, subject, comparison):
    """`fit` with the chosen body's proportions and lengths, the comparison and the full calibration's factors
    and lengths recorded (for inspection, and to reuse the measurement)."""
    chosen = comparison.chosen
    record = {**(fit.silhouettes or {}), "body_check": {
        **comparison.as_dict(), "fitted_factors": dict(fit.proportions.factors),
        "fitted_overall": fit.proportions.overall, "fitted_lengths_m": dict(fit.lengths)}}
    proportions = candidate_bodies(fit)[chosen]
    lengths = dict(fit.subject_lengths) if chosen == "rig" else segment_lengths(scaled_body(subject, proportions))
    return dataclasses.replace(fit, proportions=proportions, lengths=lengths, silhouettes=record)
