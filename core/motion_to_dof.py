"""Motion-capture clips in the tracker's DOF space (for the anatomical prior and the dynamics).

The clip is retargeted onto the body's own armature (core/mocap/retarget.py: rest-direction
alignment, T-pose vs A-pose), then each frame's bone matrices are fitted with the body's DOF.
"""
import numpy as np

from .mocap.retarget import retarget
from .pose_fitting import fit_pose_sequence


def driven_bone_indices(body):
    bones = {body.root_bone}
    for d in body.dofs:
        bones.update(t.bone for t in d.targets)
    return np.array(sorted(bones))


def dof_sequence_from_clip(body, clip, frames=None, name_map=None):
    """(F,D) DOF vectors reproducing the clip on the body, and the per-frame RMS head residual (m)."""
    sk = body.skeleton
    order = sk.order  # the retargeter wants parents before children
    position = np.empty_like(order)
    position[order] = np.arange(len(order))
    names = [sk.bone_names[b] for b in order]
    parents = np.array([position[sk.parents[b]] if sk.parents[b] >= 0 else -1 for b in order])
    if frames is not None:
        clip = clip.subset(frames)
    result = retarget(clip, sk.rest[order], parents, names, name_map=name_map)
    pose_arm = result.pose_matrices[:, position]  # back to the skeleton's bone order
    world = sk.armature_matrix @ pose_arm
    heads = world[..., :3, 3]
    rots = world[..., :3, :3]
    # Orientations only settle the twists; weighted low because the clip moves bones (clavicles,
    # hands) and axes (knee abduction) the 30-DOF body does not have.
    return fit_pose_sequence(body, heads, rots, driven_bone_indices(body), rot_weight=0.03)
