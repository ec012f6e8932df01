"""Where the landmark model looks: square crops around the projected joints of the poses the person is
expected near, one per camera. The tracker, `evaluate --capture`, `bench` and tools/landmark_offsets.py all
place the crops here, so the evidence they measure is the evidence the tracker gets."""
from __future__ import annotations

import numpy as np

from .learned import crop_around, locate


def crops_around(body, cameras, poses):
    """One CropBox per camera around the joints of `poses` (absolute DOF vectors, (D,) or (P,D): the box
    holds every pose's joints, e.g. the last estimate and its constant-velocity step)."""
    joints = body.joint_positions(np.atleast_2d(poses)).reshape(-1, 3)
    return [crop_around(cam.project(joints)) for cam in cameras]


def evidence_around(model, body, cameras, images, poses, foreground=None):
    """Learned evidence per camera (core/evidence/learned.locate) from crops around `poses`; `images`: the
    frames in camera order; `foreground(i)`: camera i's foreground mask, asked for where the crop lost the
    person."""
    return locate(model, list(images), crops_around(body, cameras, poses), foreground=foreground)
