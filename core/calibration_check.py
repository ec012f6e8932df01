"""Keep an actor calibration only where it fits the person better than the user's rig as it is.

The landmark fit and the masks' refinement can return a body that is further from the actor than the rig:
on a build the landmarks misread (sample_scenes/actor3: a short trunk on long legs came out as a normal trunk on
short legs, spine +9 %, thigh -12 %) tracking with it was worse than without (18.4 -> 21.0 mm), and on a take
whose actor IS the rig (walk) any fitted deviation only adds error. The person masks of the calibration frames
tell the cases apart when each body gets its own poses: every frame refitted to the masks (and landmarks) by the
tracker's local fit, from the poses tracked with the rig for the rig, from the landmark fit's for the calibrated
body, then the XOR / model area of core/proportions_silhouette.SilhouetteCost. Measured (20 frames, seed 0),
rig / calibrated / true proportions: actor 0.219 / 0.159 / 0.147, actor2 0.239 / 0.179 / 0.169, actor3
0.138 / 0.159 / 0.126, walk (true = rig) 0.133 / 0.147: the calibrated body is worse than the rig exactly where
tracking with it was.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .proportions import Proportions


@dataclasses.dataclass
class RigComparison:
    rig: float         # mean XOR / model area over the calibration frames' views, the rig as it is
    calibrated: float  # the same for the calibrated body

    @property
    def calibration_helps(self):
        return self.calibrated < self.rig

    def as_dict(self):
        return {"rig": self.rig, "calibrated": self.calibrated, "kept": "calibrated" if self.calibration_helps
                else "rig"}


def rig_proportions(fit):
    """The rig's own proportions in the fit's segment keys (every factor 1)."""
    return Proportions({k: 1.0 for k in fit.proportions.factors}, 1.0)


def compare_with_rig(fit, subject, tracker, targets, rig_poses):
    """RigComparison for `fit` (a ProportionsFit, the masks' refinement done) of `subject`'s tracked frames.
    targets: the CalibrationTargets of fit.frames (core/proportions_silhouette.calibration_targets, the ones the
    refinement used); rig_poses (F,D): those frames as tracked with the rig."""
    rig_cost, calibrated_cost = mask_mismatch(
        subject, tracker.proxy, targets.cameras, targets.masks,
        [(rig_proportions(fit), rig_poses), (fit.proportions, fit.poses)], targets.keypoints,
        targets.resolution(tracker), tracker.settings.backend)
    return RigComparison(rig_cost, calibrated_cost)


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


def keep_if_better(fit, comparison):
    """`fit` with the comparison recorded, or, where the calibrated body matched the masks worse than the rig,
    the rig's own proportions (the fitted ones kept in the record for inspection)."""
    record = {**(fit.silhouettes or {}), "rig_check": comparison.as_dict()}
    if comparison.calibration_helps:
        return dataclasses.replace(fit, silhouettes=record)
    record["rig_check"]["fitted_factors"] = dict(fit.proportions.factors)
    record["rig_check"]["fitted_lengths_m"] = dict(fit.lengths)
    return dataclasses.replace(fit, proportions=rig_proportions(fit), lengths=dict(fit.subject_lengths),
                               silhouettes=record)
