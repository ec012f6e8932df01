"""Retarget a MotionClip onto a target armature (bpy-free).

The target is described the way Blender stores it: per bone the rest matrix `matrix_local`
(armature space, bone Y axis along the bone), the parent index and the name. Rest poses may
differ (MakeHuman A-pose vs CMU T-pose, 131_01's arms-down rest): per target bone b we take the
minimal rotation A_b that turns the target bone's rest direction onto the source segment's rest
direction (both in the target frame), then at time t

    O_b(t) = D W_s(t) D^-1 A_b R_rest_b

where W_s is the source joint's world rotation relative to its rest, D = facing yaw @ C and C the
axis change BVH Y-up -> Blender Z-up, (x, y, z) -> (x, -z, y). Twist comes from the source; the
bone keeps its own roll. Blender composes pose = parent_pose @ (parent_rest^-1 @ rest) @ basis, so
basis_b = R_rest_b^T R_rest_p O_p^T O_b. Unmapped bones keep basis = identity (rest relative to
their parent).
"""
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

# target (MakeHuman "cmu_mb" rig) -> source joint, for the two CMU BVH namings.
# 01_01.bvh uses the MotionBuilder-friendly names (same as the rig except the finger tips);
# 131_01.bvh uses the older names. One row per target bone.
# LHipJoint/RHipJoint are left out on purpose: they are rigid pelvis links whose rest directions
# differ between the skeletons (sideways in MakeHuman, down-and-out in CMU); aligning them would
# move the hip joints even in the rest pose. Unmapped, they follow Hips rigidly.
CMU_NAME_TABLE = [
    # target            MotionBuilder-friendly   131_01-style
    ("Hips",             "Hips",            "Hips"),
    ("LeftUpLeg",        "LeftUpLeg",       "LeftHip"),
    ("LeftLeg",          "LeftLeg",         "LeftKnee"),
    ("LeftFoot",         "LeftFoot",        "LeftAnkle"),
    ("LeftToeBase",      "LeftToeBase",     "LeftToe"),
    ("RightUpLeg",       "RightUpLeg",      "RightHip"),
    ("RightLeg",         "RightLeg",        "RightKnee"),
    ("RightFoot",        "RightFoot",       "RightAnkle"),
    ("RightToeBase",     "RightToeBase",    "RightToe"),
    ("LowerBack",        "LowerBack",       "lowerback"),
    ("Spine",            "Spine",           "Chest"),
    ("Spine1",           "Spine1",          "Chest2"),
    ("Neck",             "Neck",            "lowerneck"),
    ("Neck1",            "Neck1",           "Neck"),
    ("Head",             "Head",            "Head"),
    ("LeftShoulder",     "LeftShoulder",    "LeftCollar"),
    ("LeftArm",          "LeftArm",         "LeftShoulder"),
    ("LeftForeArm",      "LeftForeArm",     "LeftElbow"),
    ("LeftHand",         "LeftHand",        "LeftWrist"),
    ("LeftFingerBase",   "LeftFingerBase",  "lhand"),
    ("LeftHandFinger1",  "LFingers",        "LFingers"),
    ("LThumb",           "LThumb",          "LThumb"),
    ("RightShoulder",    "RightShoulder",   "RightCollar"),
    ("RightArm",         "RightArm",        "RightShoulder"),
    ("RightForeArm",     "RightForeArm",    "RightElbow"),
    ("RightHand",        "RightHand",       "RightWrist"),
    ("RightFingerBase",  "RightFingerBase", "rhand"),
    ("RightHandFinger1", "RFingers",        "RFingers"),
    ("RThumb",           "RThumb",          "RThumb"),
]

# Bones that stand in the same anatomical rest posture in both skeletons (an upright trunk, the
# collar bones): they take the source's rotation away from ITS rest directly, without the rest
# direction alignment A_b. Aligning them would tilt the trunk or lift the shoulders even in the
# rest pose, because the joints sit at slightly different places in the two skeletons. A_b is for
# the limbs, whose rest postures really differ (T-pose arms vs A-pose arms).
UNALIGNED_BONES = frozenset({"Hips", "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head",
                             "LeftShoulder", "RightShoulder"})

# BVH / ASF Y-up -> Blender Z-up
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


class RetargetError(InputError):
    """The clip and the target armature cannot be matched; the message says what to change."""


def cmu_name_map(source_joint_names):
    """The target->source map of CMU_NAME_TABLE for whichever naming the source uses."""
    names = set(source_joint_names)
    best = None
    for col in (1, 2):
        m = {row[0]: row[col] for row in CMU_NAME_TABLE if row[col] in names}
        if best is None or len(m) > len(best):
            best = m
    if len(best) < len(CMU_NAME_TABLE) // 2:
        raise RetargetError("the clip's joint names match neither CMU naming in CMU_NAME_TABLE; "
                            "pass name_map={target_bone: source_joint} explicitly")
    return best


def rotation_between(a, b):
    """Minimal rotation matrix turning unit direction a onto b (the axis is a x b)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = np.linalg.norm(v)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # opposite: half turn about any axis perpendicular to a
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        perp /= np.linalg.norm(perp)
        return 2.0 * np.outer(perp, perp) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s ** 2)


def yaw_matrix(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class RetargetResult:
    bone_names: list
    basis_rotations: np.ndarray   # (F, B, 3, 3) pose-bone matrix_basis rotations
    root_location: np.ndarray     # (F, 3) matrix_basis translation of the root bone (bone space)
    pose_matrices: np.ndarray     # (F, B, 4, 4) armature-space pose matrices (head = [:3, 3])
    fps: float
    world_alignment: np.ndarray   # (3, 3) D: source world -> target world rotation
    root_scale: float

    def head_positions(self):
        return self.pose_matrices[..., :3, 3]


def _children(parents):
    ch = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            ch[p].append(j)
    return ch


def _source_direction(parents, Q, end_sites, s, toward):
    """Rest direction of source joint s's segment toward joint `toward` (a descendant, or None),
    walking on through zero-length links (CMU BVHs put Neck and the collars on Spine1).
    Q: (J, 3) rest joints and end_sites {joint: offset}, both already in the target frame."""
    children = _children(parents)
    cur = toward
    for _ in range(len(parents)):
        if cur is None:
            break
        v = Q[cur] - Q[s]
        if np.linalg.norm(v) > 1e-6:
            return v
        cur = children[cur][0] if children[cur] else None
    if s in end_sites and np.linalg.norm(end_sites[s]) > 1e-9:
        return end_sites[s]
    for c in children[s]:
        v = Q[c] - Q[s]
        if np.linalg.norm(v) > 1e-6:
            return v
    return None


def _is_descendant(parents, node, ancestor):
    while node >= 0:
        if node == ancestor:
            return True
        node = parents[node]
    return False


def _leg_height(points, up_axis, root_point):
    return float(root_point[up_axis] - points[:, up_axis].min())


def retarget(clip, target_rest, target_parents, target_names, name_map=None, root_scale="legs",
             facing_pair=("LeftUpLeg", "RightUpLeg"), translation=(0.0, 0.0, 0.0), up_axis_change=True,
             target_tails=None, unaligned=UNALIGNED_BONES):
    """Map `clip` onto the target armature. Returns a RetargetResult.

    target_rest: (B, 4, 4) Blender `bone.matrix_local` (armature space, metres);
    target_parents: (B,) parent index or -1; target_names: B names;
    name_map: {target bone: source joint}; default: the CMU table matching the clip's names;
    root_scale: "legs" scales the root trajectory by target/source leg height (keeps the feet on
      the floor when the subjects differ in size), or a number (1.0 = the source's metres);
    facing_pair: target bones whose heads (and whose mapped source joints) define left->right,
      used to turn the source so both face the same way;
    translation: added to the root position (target frame, metres);
    up_axis_change: apply C (Y-up -> Z-up); False when the source is already Z-up;
    target_tails: (B, 3) bone tails, used with the heads to measure the target's leg height;
    unaligned: target bones that skip the rest-direction alignment (see UNALIGNED_BONES)."""
    target_rest = np.asarray(target_rest, dtype=np.float64)
    target_parents = np.asarray(target_parents, dtype=np.int64)
    B = len(target_names)
    if target_rest.shape != (B, 4, 4) or target_parents.shape != (B,):
        raise RetargetError(f"target_rest must be ({B},4,4) and target_parents ({B},), got "
                            f"{target_rest.shape} and {target_parents.shape}")
    for b, p in enumerate(target_parents):
        if p >= b:
            raise RetargetError(f"target bone {target_names[b]!r} is listed before its parent; list parents first")
    if name_map is None:
        name_map = cmu_name_map(clip.joint_names)
    src_idx = {}
    for t, s in name_map.items():
        if t not in target_names:
            raise RetargetError(f"name_map names target bone {t!r}, which the armature does not have")
        if s not in clip.joint_names:
            raise RetargetError(f"name_map maps {t!r} to source joint {s!r}, which the clip does not have")
        src_idx[target_names.index(t)] = clip.joint_names.index(s)
    roots = [b for b in range(B) if target_parents[b] < 0]
    if len(roots) != 1 or roots[0] not in src_idx:
        raise RetargetError("the target needs exactly one root bone, mapped to the source root")
    root_b = roots[0]

    C = Y_UP_TO_Z_UP if up_axis_change else np.eye(3)
    u = clip.units_to_metres
    Ps = clip.rest_positions()
    Q = (Ps @ C.T) * u                      # source rest joints, target axes, metres
    heads = target_rest[:, :3, 3]
    Rr = target_rest[:, :3, :3]

    # facing: yaw so the source's left->right direction matches the target's
    yaw = np.eye(3)
    la, ra = (target_names.index(n) if n in target_names else None for n in facing_pair)
    if la is not None and ra is not None and la in src_idx and ra in src_idx:
        vt = heads[la] - heads[ra]
        vs = Q[src_idx[la]] - Q[src_idx[ra]]
        ang = np.arctan2(vt[1], vt[0]) - np.arctan2(vs[1], vs[0])
        yaw = yaw_matrix(ang)
    D = yaw @ C
    Q = Q @ yaw.T
    end_sites_t = {j: (D @ e) * u for j, e in clip.end_sites.items()}

    # per-bone alignment A_b
    t_children = _children(target_parents)
    A = np.tile(np.eye(3), (B, 1, 1))
    for b, s in src_idx.items():
        if target_names[b] in unaligned:
            continue
        tail_dir = Rr[b][:, 1]
        # target child continuing this bone: the mapped child whose head lies most nearly along the
        # bone (children sharing the bone's head, like the CMU hip joints on Hips, rank last)
        toward = None
        best = -np.inf
        for c in t_children[b]:
            if c in src_idx and _is_descendant(clip.parents, src_idx[c], s) and src_idx[c] != s:
                offset = heads[c] - heads[b]
                length = np.linalg.norm(offset)
                along = offset @ tail_dir / length if length > 1e-6 else -2.0
                if along > best:
                    best, toward = along, src_idx[c]
        v = _source_direction(clip.parents, Q, end_sites_t, s, toward)
        if v is not None:
            A[b] = rotation_between(tail_dir, v)

    W = clip.world_rotations_from_rest()             # (F, J, 3, 3)
    F = W.shape[0]
    Ot = np.empty((F, B, 3, 3))                      # O_b(t) of the module docstring
    for b in range(B):
        if b in src_idx:
            Ot[:, b] = D @ W[:, src_idx[b]] @ D.T @ (A[b] @ Rr[b])
        else:
            p = target_parents[b]
            Ot[:, b] = Ot[:, p] @ (Rr[p].T @ Rr[b])
    basis = np.empty_like(Ot)
    for b in range(B):
        p = target_parents[b]
        if p < 0:
            basis[:, b] = Rr[b].T @ Ot[:, b]
        else:
            basis[:, b] = Rr[b].T @ Rr[p] @ np.swapaxes(Ot[:, p], -1, -2) @ Ot[:, b]

    # root trajectory
    if root_scale == "legs":
        src_pts = np.vstack([Q] + [Q[j] + e for j, e in end_sites_t.items()])
        tgt_pts = heads if target_tails is None else np.vstack([heads, np.asarray(target_tails, float)])
        s_leg = _leg_height(src_pts, 2, Q[src_idx[root_b]])
        t_leg = _leg_height(tgt_pts, 2, heads[root_b])
        if s_leg <= 0 or t_leg <= 0:
            raise RetargetError("cannot measure leg height for root_scale='legs'; pass a number")
        scale = t_leg / s_leg
    else:
        scale = float(root_scale)
    src_root = clip.root_positions + clip.offsets[clip.parents.argmin()]
    root_world = (src_root @ D.T) * u * scale + np.asarray(translation, dtype=np.float64)
    root_loc = (root_world - heads[root_b]) @ Rr[root_b]   # Rr^T (p - head), row-wise

    # armature-space pose matrices: pose = parent_pose @ (parent_rest^-1 @ rest) @ basis
    basis4 = np.zeros((F, B, 4, 4))
    basis4[..., :3, :3] = basis
    basis4[..., 3, 3] = 1.0
    basis4[:, root_b, :3, 3] = root_loc
    pose = np.empty_like(basis4)
    inv_rest = np.linalg.inv(target_rest)
    for b in range(B):
        p = target_parents[b]
        if p < 0:
            pose[:, b] = target_rest[b] @ basis4[:, b]
        else:
            pose[:, b] = pose[:, p] @ (inv_rest[p] @ target_rest[b]) @ basis4[:, b]
    return RetargetResult(list(target_names), basis, root_loc, pose, clip.fps, D, scale)

