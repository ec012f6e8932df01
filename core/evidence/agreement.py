"""How well a result fits footage without ground truth: the learned evidence, found afresh around each
solved pose, against the tracked model.

Per view and frame:
  coverage   the share of the model's projected silhouette that the learned person mask covers
  iou        the model silhouette's IoU with the learned mask (within the crop the model looked at)
  keypoint   the median distance (image pixels) between the landmarks seen (visibility >= 0.5) and the
             projected rig points they stand for, each left/right pair in its better assignment
A model that drifted off the person loses coverage and gains keypoint distance at once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .crops import evidence_around
from ..render.model_mask import model_mask

MIN_VISIBILITY = 0.5


@dataclass
class ViewAgreement:
    coverage: float
    iou: float
    keypoint_px: float


def view_agreement(camera, evidence, vertices, faces, rig_uv, rig_points):
    """One view: the model's mask and rig points (K,2) against that view's ViewEvidence."""
    model = model_mask(camera, vertices, faces)
    if not evidence.found or not model.any():
        return ViewAgreement(float("nan"), float("nan"), float("nan"))
    person = evidence.mask
    coverage = float((model & person).sum() / model.sum())
    iou = float((model & person).sum() / max(1, (model | person).sum()))
    landmarks = evidence.keypoints[rig_points.landmarks]
    visible = evidence.visibility[rig_points.landmarks] >= MIN_VISIBILITY
    same = np.linalg.norm(rig_uv - landmarks, axis=1)
    crossed = np.linalg.norm(rig_uv - landmarks[rig_points.swap], axis=1)
    swap = crossed + crossed[rig_points.swap] < same + same[rig_points.swap]
    distance = np.where(swap, crossed, same)
    ok = np.where(swap, visible[rig_points.swap], visible)
    return ViewAgreement(coverage, iou, float(np.median(distance[ok])) if ok.any() else float("nan"))


def result_agreement(body, proxy, cameras, read_frame, frames, poses, rig_points, model):
    """{camera name: [ViewAgreement per frame]} for a result's frames and poses (absolute DOF vectors)."""
    out = {cam.name: [] for cam in cameras}
    for frame, pose in zip(frames, poses):
        images = read_frame(int(frame))
        evidence = evidence_around(model, body, cameras, [images[c.name] for c in cameras], pose)
        vertices = proxy.deform(body, pose[None])[0]
        points = rig_points.world(body, pose[None])[0]
        for cam, ev in zip(cameras, evidence):
            out[cam.name].append(view_agreement(cam, ev, vertices, proxy.faces, cam.project(points), rig_points))
    return out


def summarise_agreement(per_view):
    """{camera: {coverage, iou, keypoint_px}} means over frames (NaN frames skipped), and 'all'."""
    def means(items):
        return {k: float(np.nanmean([getattr(a, k) for a in items])) if items else float("nan")
                for k in ("coverage", "iou", "keypoint_px")}

    summary = {name: means(items) for name, items in per_view.items()}
    summary["all"] = means([a for items in per_view.values() for a in items])
    return summary
