"""Motion-capture clips in the tracker's DOF space (for the anatomical prior and the dynamics).

The clip is retargeted onto the body's own armature (core/mocap/retarget.py: rest-direction
alignment, T-pose vs A-pose), then each frame's bone matrices are fitted with the body's DOF.
"""
import numpy as np

from .retarget import UNALIGNED_BONES, cmu_name_map, retarget
from ..body.pose_fit import fit_pose_sequence


def driven_bone_indices(body):
    bones = {body.root_bone}
    for d in body.dofs:
        bones.update(t.bone for t in d.targets)
    return np.array(sorted(bones))


def role_name_map(body, source_joint_names):
    """{target bone: source joint}, the bones that skip the rest alignment, and the left/right hip bones, for
    a rig that is not CMU-named (Mixamo, Rigify): each role's bones paired in chain order with the CMU
    preset's bones of that role (a Mixamo "Spine" is CMU's "LowerBack"), then the remaining bones whose name
    without a namespace is a CMU name ("mixamorig:LeftHand"), each mapped to the clip's joint for that name."""
    from ..body.rig_presets import PRESETS

    cmu = cmu_name_map(source_joint_names)
    as_cmu = {}
    for role, bones in body.roles.items():
        for target, cmu_name in zip(bones, PRESETS["cmu"].get(role, ())):
            as_cmu[target] = cmu_name
    paired = set(as_cmu.values())
    for name in body.skeleton.bone_names:
        bare = name.split(":")[-1]
        if name not in as_cmu and bare in cmu and bare not in paired:
            as_cmu[name] = bare
    name_map = {t: cmu[c] for t, c in as_cmu.items() if c in cmu}
    unaligned = frozenset(t for t, c in as_cmu.items() if c in UNALIGNED_BONES)
    return name_map, unaligned, (body.roles["l_hip"][0], body.roles["r_hip"][0])


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
    options = {}
    if name_map is None and body.preset not in ("cmu", ""):
        name_map, unaligned, hips = role_name_map(body, clip.joint_names)
        options = {"unaligned": unaligned, "facing_pair": hips}
    result = retarget(clip, sk.rest[order], parents, names, name_map=name_map, **options)
    pose_arm = result.pose_matrices[:, position]  # back to the skeleton's bone order
    world = sk.armature_matrix @ pose_arm
    heads = world[..., :3, 3]
    rots = world[..., :3, :3]
    # Orientations only settle the twists; weighted low because the clip moves bones (clavicles,
    # hands) and axes (knee abduction) the 30-DOF body does not have.
    return fit_pose_sequence(body, heads, rots, driven_bone_indices(body), rot_weight=0.03)
