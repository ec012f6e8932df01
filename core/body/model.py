"""The posable, skinned body: skeleton, degrees of freedom, forward kinematics, linear blend skinning.

Conventions follow Blender so the tracker's pose keys straight onto the user's armature:
* `rest` (B,4,4) is each bone's rest matrix in armature space (Blender `bone.matrix_local`:
  origin at the head, Y along the bone);
* a bone's pose matrix is `pose[parent] @ inv(rest[parent]) @ rest[b] @ basis[b]`, where `basis`
  is the pose bone's `matrix_basis` (location, rotation);
* a rest-pose vertex v (armature space) moves to `sum_b w_b pose[b] inv(rest[b]) v` (linear blend
  skinning, weights normalised per vertex like Blender's Armature modifier);
* everything is batched over P poses at once: poses (P,D) -> bone matrices (P,B,4,4) ->
  vertices (P,V,3), with Python loops over bones only (about 30), never over poses.

The pose vector: root translation (world position of the root bone's head, metres), root rotation
(rotation vector in world axes, applied on top of `root_anchor` @ rest orientation), then joint
angles in radians about anatomical axes fixed in each bone's rest frame.
"""
import functools
from dataclasses import dataclass, field

import numpy as np

from . import rig_presets
from .rig_presets import ROLE_BY_NAME, RigMappingError
from .rotations import axis_angle_matrix, rigid_inverse, rotvec_to_matrix

TRANSLATION_SCALE = 0.02  # metres: per-DOF scale s of algorithms.md 1.6
ANGLE_SCALE = np.deg2rad(5.0)


@dataclass
class DofTarget:
    bone: int
    axis_local: np.ndarray  # unit axis in the bone's rest frame
    share: float = 1.0


@dataclass
class Dof:
    name: str
    kind: str  # "translation", "root_rotation" or "angle"
    lower: float
    upper: float
    role: str = ""
    prior_group: str = ""
    targets: list = field(default_factory=list)


@dataclass
class Skeleton:
    bone_names: list
    parents: np.ndarray  # (B,) parent index, -1 for top-level bones
    rest: np.ndarray  # (B,4,4) armature space
    armature_matrix: np.ndarray = field(default_factory=lambda: np.eye(4))  # world <- armature

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.rest = np.asarray(self.rest, dtype=np.float64)
        self.armature_matrix = np.asarray(self.armature_matrix, dtype=np.float64)
        self.index = {n: i for i, n in enumerate(self.bone_names)}
        self.order = _topological_order(self.parents)
        inv_rest = rigid_inverse(self.rest)
        self.inv_rest = inv_rest
        rel = self.rest.copy()
        has_parent = self.parents >= 0
        rel[has_parent] = inv_rest[self.parents[has_parent]] @ self.rest[has_parent]
        self.rest_relative = rel
        A_lin = self.armature_matrix[:3, :3]
        self.armature_scale = float(np.cbrt(np.linalg.det(A_lin)))
        self.armature_rotation = A_lin / self.armature_scale
        self.armature_inverse = np.linalg.inv(self.armature_matrix)

    @property
    def n_bones(self):
        return len(self.bone_names)

    def rest_heads_world(self):
        return (self.armature_matrix @ self.rest)[:, :3, 3]

    def children_of(self, b):
        return [i for i, p in enumerate(self.parents) if p == b]

    def is_ancestor(self, a, b):
        """True if bone a is b or one of b's ancestors."""
        while b >= 0:
            if a == b:
                return True
            b = self.parents[b]
        return False


def _topological_order(parents):
    order, seen = [], set()

    def visit(b):
        if b in seen:
            return
        if parents[b] >= 0:
            visit(int(parents[b]))
        seen.add(b)
        order.append(b)

    for b in range(len(parents)):
        visit(b)
    return np.array(order, dtype=np.int64)


@dataclass
class BodyFrame:
    """Anatomical axes of the rest pose, in armature space."""

    left: np.ndarray
    forward: np.ndarray
    up: np.ndarray

    def resolve(self, name):
        sign = -1.0 if name.startswith("-") else 1.0
        return sign * getattr(self, name.lstrip("-"))


class Body:
    """Skeleton + DOF + skinned mesh. Build it with `build_body` (or the Blender bridge)."""

    def __init__(self, skeleton, dofs, vertices, faces, weights, root_bone, roles=None, preset=""):
        self.skeleton = skeleton
        self.dofs = list(dofs)
        self.vertices = np.asarray(vertices, dtype=np.float64)  # rest, armature space
        self.faces = np.asarray(faces, dtype=np.int64)
        w = np.asarray(weights, dtype=np.float64)
        total = w.sum(axis=1, keepdims=True)
        self.weights = np.divide(w, total, out=np.zeros_like(w), where=total > 0)
        self.unweighted = total[:, 0] <= 0  # such vertices stay where they are, as in Blender
        self.root_bone = int(root_bone)
        self.roles = dict(roles or {})
        self.preset = preset
        self._last_skinning = None  # (poses, matrices) of the last skinning_matrices call
        self._compile()

    # ------------------------------------------------------------------ layout
    def _compile(self):
        B = self.skeleton.n_bones
        self.bone_dofs = [[] for _ in range(B)]  # per bone: (dof index, axis_local, share), multiplication order
        for i, dof in enumerate(self.dofs):
            for tgt in dof.targets:
                self.bone_dofs[tgt.bone].append((i, np.asarray(tgt.axis_local, float), float(tgt.share)))
        # The same rotations flattened, so local_bases makes all of them in one call (the root's own
        # basis is built from its rotation vector instead).
        terms = [(b, i, axis, share) for b in range(B) if b != self.root_bone for i, axis, share in self.bone_dofs[b]]
        self._term_dof = np.array([t[1] for t in terms], dtype=np.int64)
        self._term_axis = np.array([t[2] for t in terms], dtype=np.float64).reshape(-1, 3)
        self._term_share = np.array([t[3] for t in terms], dtype=np.float64)
        term_bones = np.array([t[0] for t in terms], dtype=np.int64)  # ascending: the terms go bone by bone
        self._term_start = np.searchsorted(term_bones, np.arange(B + 1)).astype(np.int64)
        self._bone_terms = {}
        for k, (b, *_rest) in enumerate(terms):
            self._bone_terms.setdefault(b, []).append(k)
        self.lower = np.array([d.lower for d in self.dofs])
        self.upper = np.array([d.upper for d in self.dofs])
        self.scale = np.array([TRANSLATION_SCALE if d.kind == "translation" else ANGLE_SCALE for d in self.dofs])
        self.dof_names = [d.name for d in self.dofs]
        self.translation_dofs = np.array([i for i, d in enumerate(self.dofs) if d.kind == "translation"])
        self.root_rotation_dofs = np.array([i for i, d in enumerate(self.dofs) if d.kind == "root_rotation"])
        self.prior_groups = {}
        for i, d in enumerate(self.dofs):
            if d.prior_group:
                self.prior_groups.setdefault(d.prior_group, []).append(i)
        self._compile_parts()

    def _compile_parts(self):
        """Body parts: each bone belongs to the nearest ancestor-or-self that a joint role drives."""
        sk = self.skeleton
        owner = {}
        for role, bones in self.roles.items():
            for name in bones:
                owner[sk.index[name]] = role
        names = ["root"] + [r for r in self.roles if r != "root"]
        part_of_role = {r: i for i, r in enumerate(names)}
        bone_part = np.zeros(sk.n_bones, dtype=np.int64)
        for b in sk.order:
            if b in owner:
                bone_part[b] = part_of_role[owner[b]]
            elif sk.parents[b] >= 0:
                bone_part[b] = bone_part[sk.parents[b]]
        self.part_names = names
        self.bone_part = bone_part

    @property
    def n_dof(self):
        return len(self.dofs)

    # ------------------------------------------------------------------ poses
    def default_pose(self):
        """Rest pose at the rest position: the pose vector whose bone matrices equal the rest."""
        x = np.zeros(self.n_dof)
        x[self.translation_dofs] = self.skeleton.rest_heads_world()[self.root_bone]
        return x

    def clamp(self, poses):
        return np.clip(poses, self.lower, self.upper)

    def local_bases(self, poses, root_anchor=None):
        """(P,D) -> (P,B,4,4): each pose bone's `matrix_basis` (what Blender keys)."""
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        P, B = poses.shape[0], self.skeleton.n_bones
        basis = np.broadcast_to(np.eye(4), (P, B, 4, 4)).copy()
        rotations = axis_angle_matrix(self._term_axis, poses[:, self._term_dof] * self._term_share)  # (P,T,3,3)
        for b, terms in self._bone_terms.items():  # each bone's rotations in multiplication order
            product = rotations[:, terms[0]]
            for k in terms[1:]:
                product = product @ rotations[:, k]
            basis[:, b, :3, :3] = product
        basis[:, self.root_bone] = self._root_basis(poses, root_anchor)
        return basis

    def _root_basis(self, poses, root_anchor):
        sk, r = self.skeleton, self.root_bone
        rest_rot = sk.rest[r, :3, :3]
        world_rest_rot = sk.armature_rotation @ rest_rot  # world orientation of the root bone at rest
        anchor = np.eye(3) if root_anchor is None else np.asarray(root_anchor, dtype=np.float64)
        R_world = rotvec_to_matrix(poses[:, self.root_rotation_dofs]) @ anchor  # (P,3,3)
        # world rotation = R_world @ world_rest_rot = A_rot @ rest_rot @ R_basis
        R_basis = world_rest_rot.T @ R_world @ world_rest_rot
        # world head = A @ (rest_head + rest_rot @ loc)  ->  loc = rest_rot^T (A^-1 t - rest_head)
        t = poses[:, self.translation_dofs]
        A_inv = sk.armature_inverse
        t_arm = t @ A_inv[:3, :3].T + A_inv[:3, 3]
        loc = (t_arm - sk.rest[r, :3, 3]) @ rest_rot  # row-vector form of rest_rot^T @ v
        out = np.broadcast_to(np.eye(4), (len(poses), 4, 4)).copy()
        out[:, :3, :3] = R_basis
        out[:, :3, 3] = loc
        return out

    def pose_matrices(self, poses, root_anchor=None, world=True):
        """(P,D) -> (P,B,4,4) bone pose matrices (world space unless world=False).

        The numba chain (core/body/kinematics_fast.py) when numba is there, else pose_matrices_reference."""
        fast = _fast_kinematics()
        if fast is None:
            return self.pose_matrices_reference(poses, root_anchor, world)
        poses = np.ascontiguousarray(np.atleast_2d(np.asarray(poses, dtype=np.float64)))
        return fast.pose_matrices(self, poses, self._root_basis(poses, root_anchor), world)

    def pose_matrices_reference(self, poses, root_anchor=None, world=True):
        """pose_matrices in NumPy: every bone's basis for the whole batch, then the chain of batched products."""
        sk = self.skeleton
        basis = self.local_bases(poses, root_anchor)
        pose = np.empty_like(basis)
        for b in sk.order:
            p = sk.parents[b]
            local = sk.rest_relative[b] @ basis[:, b]
            pose[:, b] = local if p < 0 else pose[:, p] @ local
        return sk.armature_matrix @ pose if world else pose

    def skinning_matrices(self, poses, root_anchor=None):
        """(P,B,4,4): world <- rest armature space, per bone (read-only).

        The likelihood asks twice for the same batch (the proxy's skin, then the landmarks' rig points), so
        the last batch's matrices are kept and given again for equal poses.
        """
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        last = self._last_skinning
        if (root_anchor is None and last is not None and last[0].shape == poses.shape
                and np.array_equal(last[0], poses)):
            return last[1]
        M = self.pose_matrices(poses, root_anchor) @ self.skeleton.inv_rest
        M.flags.writeable = False
        if root_anchor is None:
            self._last_skinning = (poses.copy(), M)
        return M

    def joint_positions(self, poses, root_anchor=None):
        """(P,B,3) world position of every bone's head."""
        return self.pose_matrices(poses, root_anchor)[:, :, :3, 3]

    def deform(self, poses, root_anchor=None, vertices=None, weights=None, unweighted=None):
        """Linear blend skinning: (P,D) -> (P,V,3) world vertices (default: the full mesh)."""
        if vertices is None:
            vertices, weights, unweighted = self.vertices, self.weights, self.unweighted
        M = self.skinning_matrices(poses, root_anchor)  # (P,B,4,4)
        return _fast_blend()(M, vertices, weights, unweighted, self.skeleton.armature_matrix)


@functools.cache
def _fast_kinematics():
    """core/body/kinematics_fast.py when numba is there, else None (the NumPy reference then)."""
    try:
        from . import kinematics_fast as fast_kinematics
    except ImportError:
        return None
    return fast_kinematics


@functools.cache
def _fast_blend():
    """The numba skinning (core/body/skinning_fast.py) when numba is there, else the NumPy reference below."""
    try:
        from .skinning_fast import blend_vertices as fast
    except ImportError:
        return blend_vertices
    return fast


def blend_vertices(skin_matrices, vertices, weights, unweighted, armature_matrix):
    """LBS core: per-vertex blended 3x4 matrices from one GEMM, then applied to the rest vertices."""
    P, B = skin_matrices.shape[:2]
    V = len(vertices)
    top = skin_matrices[:, :, :3, :].transpose(1, 0, 2, 3).reshape(B, P * 12)
    blended = (weights @ top).reshape(V, P, 3, 4)  # (V,B) @ (B,P*12)
    out = np.einsum("vpij,vj->vpi", blended[..., :3], vertices) + blended[..., 3]  # (V,P,3)
    out = out.transpose(1, 0, 2)
    if unweighted is not None and np.any(unweighted):
        static = vertices[unweighted] @ armature_matrix[:3, :3].T + armature_matrix[:3, 3]
        out[:, unweighted] = static
    return out


# ---------------------------------------------------------------------- building a body
def body_frame(skeleton, roles):
    rest = skeleton.rest
    idx = skeleton.index
    root_head = rest[idx[roles["root"][0]], :3, 3]
    neck_head = rest[idx[roles["neck"][0]], :3, 3]
    up = neck_head - root_head
    up /= np.linalg.norm(up)
    left = rest[idx[roles["l_hip"][0]], :3, 3] - rest[idx[roles["r_hip"][0]], :3, 3]
    left -= up * (left @ up)
    norm = np.linalg.norm(left)
    if norm < 1e-9:
        raise RigMappingError("cannot tell left from right: the left and right hip bones share a head position")
    left /= norm
    forward = np.cross(left, up)
    return BodyFrame(left=left, forward=forward, up=up)


def _motion_direction(frame, spec, motion):
    if motion == "out":
        return frame.left if spec.side != "r" else -frame.left
    return frame.resolve(motion)


def _swing_axis(bone_dir, motion_dir):
    """Axis that moves a bone pointing along bone_dir towards motion_dir; None if they are parallel."""
    axis = np.cross(bone_dir, motion_dir)
    norm = np.linalg.norm(axis)
    return axis / norm if norm > 0.3 else None


def _bone_axes(skeleton, frame, spec, bone):
    """Rotation axes (armature space) of one bone for a role, and the hinge's rest bend."""
    d = skeleton.rest[bone, :3, 1]
    mirror = -1.0 if spec.side == "r" else 1.0
    axes, rest_bend = [], 0.0
    for ax in spec.axes:
        if ax.motion == "along":
            axes.append(mirror * d)
            continue
        axis = _swing_axis(d, _motion_direction(frame, spec, ax.motion))
        if axis is None and axes:
            # Limb along the motion direction (abduction of a T-pose arm): swing in the plane
            # perpendicular to the first axis instead.
            axis = mirror * np.cross(axes[0], d)
            axis /= np.linalg.norm(axis)
        if axis is None:
            raise RigMappingError(f"bone {skeleton.bone_names[bone]!r} points along its {ax.motion} "
                                  f"motion: cannot orient its {spec.role} {ax.name} axis")
        if spec.kind == "hinge":
            axis, rest_bend = _hinge_axis(skeleton, bone, axis)
        axes.append(axis)
    return axes, rest_bend


def _hinge_axis(skeleton, bone, anatomical_axis):
    """A bent hinge at rest reveals its true axis: the normal of the plane of the two bones."""
    child_dir = skeleton.rest[bone, :3, 1]
    parent = skeleton.parents[bone]
    parent_dir = skeleton.rest[parent, :3, 1] if parent >= 0 else child_dir
    normal = np.cross(parent_dir, child_dir)
    bend = np.arctan2(np.linalg.norm(normal), parent_dir @ child_dir)
    if bend > np.deg2rad(10):
        axis = normal / np.linalg.norm(normal)
        if axis @ anatomical_axis < 0:  # bent the anatomically negative way at rest
            return -axis, -bend
        return axis, bend
    return anatomical_axis, float(np.arctan2(normal @ anatomical_axis, parent_dir @ child_dir))


def _role_dofs(skeleton, frame, role, bones):
    spec = ROLE_BY_NAME[role]
    idx = [skeleton.index[n] for n in bones]
    share = 1.0 / len(idx)
    per_bone = [_bone_axes(skeleton, frame, spec, b) for b in idx]
    dofs = []
    for k, ax in enumerate(spec.axes):
        lower, upper = np.deg2rad(ax.lower_deg), np.deg2rad(ax.upper_deg)
        if spec.kind == "hinge":
            rest_bend = per_bone[0][1]
            lower, upper = min(0.0, -rest_bend) - np.deg2rad(5), upper - rest_bend
        targets = [DofTarget(b, skeleton.rest[b, :3, :3].T @ axes[k], share) for b, (axes, _) in zip(idx, per_bone)]
        dofs.append(Dof(f"{role}.{ax.name}", "angle", lower, upper, role, spec.prior_group, targets))
    return dofs


def _user_dofs(skeleton, bone_name, user_spec):
    """DOF from the armature itself: unlocked local Euler axes with their Limit Rotation limits.

    user_spec: {"order": "XYZ", "axes": {"X": (min, max) or None, ...}} with only unlocked axes listed.
    Blender's Euler 'XYZ' applies X first, i.e. R = Rz @ Ry @ Rx: multiply in reversed order.
    """
    b = skeleton.index[bone_name]
    order = user_spec.get("order", "XYZ")
    dofs = []
    for letter in reversed(order):
        if letter not in user_spec["axes"]:
            continue
        limits = user_spec["axes"][letter] or (-np.pi, np.pi)
        axis = np.eye(3)["XYZ".index(letter)]
        dofs.append(Dof(f"{bone_name}.rot{letter.lower()}", "angle", float(limits[0]), float(limits[1]),
                        bone_name, "", [DofTarget(b, axis, 1.0)]))
    return dofs


def build_body(skeleton, vertices, faces, weights, user_dofs=None):
    """Map the rig onto the tracker's DOF layout and return a Body.

    vertices: rest positions in armature space; weights (V,B) by bone index (zero for bones that do
    not deform). user_dofs: {bone name: spec} for bones whose rotation locks or Limit Rotation
    constraints the user set (see `_user_dofs`); they replace the preset's axes for that bone.
    """
    preset, roles = rig_presets.match_preset(skeleton.bone_names)
    frame = body_frame(skeleton, roles)
    user_dofs = dict(user_dofs or {})
    root = skeleton.index[roles["root"][0]]
    dofs = [Dof(f"root.t{a}", "translation", -np.inf, np.inf, "root") for a in "xyz"]
    dofs += [Dof(f"root.r{a}", "root_rotation", -np.inf, np.inf, "root") for a in "xyz"]
    for role, bones in roles.items():
        if role == "root":
            continue
        if any(b in user_dofs for b in bones):
            for b in bones:
                spec = user_dofs.pop(b, None)
                if spec is not None:
                    group = ROLE_BY_NAME[role].prior_group
                    for d in _user_dofs(skeleton, b, spec):
                        d.role, d.prior_group = role, group
                        dofs.append(d)
            continue
        dofs += _role_dofs(skeleton, frame, role, bones)
    for bone_name, spec in user_dofs.items():  # extra bones the user opened up
        if bone_name != roles["root"][0]:
            dofs += _user_dofs(skeleton, bone_name, spec)
    return Body(skeleton, dofs, vertices, faces, weights, root, roles, preset)
