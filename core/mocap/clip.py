"""MotionClip: a skeleton (names, parents, rest offsets and frames) and its animation.

One data structure serves BVH and ASF/AMC so the retargeting and the tracker's priors never care
which file a motion came from.

Conventions (column vectors, rotations act on the left):
* `offsets[j]` is where joint j sits relative to its parent in the *rest* pose, expressed in the
  world axes of the rest pose (BVH OFFSET; for ASF the parent bone's direction * length).
* `rest_rotations[j]` is the orientation of joint j's own axis frame in the rest pose (identity for
  BVH, the ASF `axis` frame for ASF). Channel rotations are expressed in that frame.
* `local_rotations[f, j]` is the channel rotation of joint j at frame f, in its axis frame.
* World rotation relative to rest: W_j = W_parent @ (S_j @ L_j @ S_j^T) with S = rest_rotation;
  joint position: p_j = p_parent + W_parent @ offsets[j]; the root adds root_positions[f].
"""
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError


class MotionFileError(InputError):
    """A motion file that cannot be read; the message names the file, the line and the fix."""


@dataclass
class MotionClip:
    joint_names: list
    parents: np.ndarray            # (J,) int, -1 for the root
    offsets: np.ndarray            # (J, 3) rest offsets from the parent, file units
    rest_rotations: np.ndarray     # (J, 3, 3) joint axis frames in the rest pose
    local_rotations: np.ndarray    # (F, J, 3, 3)
    root_positions: np.ndarray     # (F, 3) file units
    fps: float
    units_to_metres: float = 1.0
    end_sites: dict = field(default_factory=dict)   # joint index -> (3,) end-site offset, file units

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.offsets = np.asarray(self.offsets, dtype=np.float64)
        self.rest_rotations = np.asarray(self.rest_rotations, dtype=np.float64)
        self.local_rotations = np.asarray(self.local_rotations, dtype=np.float64)
        self.root_positions = np.asarray(self.root_positions, dtype=np.float64)
        J = len(self.joint_names)
        F = self.local_rotations.shape[0]
        if self.parents.shape != (J,) or self.offsets.shape != (J, 3):
            raise ValueError(f"MotionClip: parents/offsets must have {J} rows, got "
                             f"{self.parents.shape} and {self.offsets.shape}")
        if self.local_rotations.shape != (F, J, 3, 3) or self.root_positions.shape != (F, 3):
            raise ValueError(f"MotionClip: local_rotations must be (F,{J},3,3) and root_positions (F,3), got "
                             f"{self.local_rotations.shape} and {self.root_positions.shape}")
        for j, p in enumerate(self.parents):
            if p >= j:
                raise ValueError(f"MotionClip: joint {self.joint_names[j]!r} comes before its parent; "
                                 "joints must be listed parents first")

    @property
    def n_frames(self):
        return self.local_rotations.shape[0]

    @property
    def n_joints(self):
        return len(self.joint_names)

    def index(self, name):
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f"joint {name!r} not in the clip; it has {', '.join(self.joint_names)}") from None

    def _frame_slice(self, frames):
        if frames is None:
            return np.arange(self.n_frames)
        frames = np.atleast_1d(np.asarray(frames, dtype=np.int64))
        if frames.size and (frames.min() < 0 or frames.max() >= self.n_frames):
            raise IndexError(f"frames must lie in 0..{self.n_frames - 1}")
        return frames

    def world_rotations_from_rest(self, frames=None):
        """(F, J, 3, 3) rotation of every joint relative to its rest orientation, in world axes."""
        idx = self._frame_slice(frames)
        S = self.rest_rotations
        L = self.local_rotations[idx]
        rel = S[None] @ L @ np.swapaxes(S, -1, -2)[None]
        W = np.empty_like(rel)
        for j, p in enumerate(self.parents):
            W[:, j] = rel[:, j] if p < 0 else W[:, p] @ rel[:, j]
        return W

    def world_transforms(self, frames=None):
        """(F, J, 4, 4) global joint frames (file units): rotation = the joint's axis frame in
        world (equals rest_rotations in the rest pose), translation = the joint position."""
        idx = self._frame_slice(frames)
        W = self.world_rotations_from_rest(idx)
        P = np.empty(W.shape[:2] + (3,))
        for j, p in enumerate(self.parents):
            if p < 0:
                P[:, j] = self.root_positions[idx] + self.offsets[j]
            else:
                P[:, j] = P[:, p] + W[:, p] @ self.offsets[j]
        T = np.zeros(W.shape[:2] + (4, 4))
        T[..., :3, :3] = W @ self.rest_rotations[None]
        T[..., :3, 3] = P
        T[..., 3, 3] = 1.0
        return T

    def world_positions(self, frames=None, metres=False):
        """(F, J, 3) joint positions, in file units or metres."""
        P = self.world_transforms(frames)[..., :3, 3]
        return P * self.units_to_metres if metres else P

    def rest_positions(self):
        """(J, 3) joint positions in the rest pose (root at the origin), file units."""
        P = np.zeros((self.n_joints, 3))
        for j, p in enumerate(self.parents):
            P[j] = self.offsets[j] if p < 0 else P[p] + self.offsets[j]
        return P

    def subset(self, frames):
        idx = self._frame_slice(frames)
        return MotionClip(list(self.joint_names), self.parents.copy(), self.offsets.copy(),
                          self.rest_rotations.copy(), self.local_rotations[idx].copy(),
                          self.root_positions[idx].copy(), self.fps, self.units_to_metres,
                          dict(self.end_sites))

    def resample(self, fps):
        """A new clip at `fps` covering the same time span: rotations slerped, root positions
        linear. An integer ratio (120 -> 30) reproduces the original frames exactly."""
        from scipy.spatial.transform import Rotation, Slerp

        if not fps > 0:
            raise ValueError(f"resample: fps must be positive, got {fps}")
        F = self.n_frames
        t_old = np.arange(F) / self.fps
        n_new = int(np.floor(t_old[-1] * fps + 1e-6)) + 1
        t_new = np.arange(n_new) / fps
        t_new = np.minimum(t_new, t_old[-1])
        local = np.empty((n_new, self.n_joints, 3, 3))
        if F == 1:
            local[:] = self.local_rotations[0]
        else:
            for j in range(self.n_joints):
                slerp = Slerp(t_old, Rotation.from_matrix(self.local_rotations[:, j]))
                local[:, j] = slerp(t_new).as_matrix()
        roots = np.stack([np.interp(t_new, t_old, self.root_positions[:, k]) for k in range(3)], axis=1)
        # snap samples that coincide with an original frame, so exact ratios stay exact
        pos = t_new * self.fps
        exact = np.abs(pos - np.round(pos)) < 1e-6
        src = np.round(pos[exact]).astype(np.int64)
        local[exact] = self.local_rotations[src]
        roots[exact] = self.root_positions[src]
        return MotionClip(list(self.joint_names), self.parents.copy(), self.offsets.copy(),
                          self.rest_rotations.copy(), local, roots, float(fps), self.units_to_metres,
                          dict(self.end_sites))


def euler_matrix(axes, angles_deg):
    """Rotation matrices for angles applied in the listed order as in BVH/ASF: for axes "ZYX" the
    matrix is Rz @ Ry @ Rx. `angles_deg` (..., len(axes)) -> (..., 3, 3)."""
    a = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), a.shape[:-1] + (3, 3)).copy()
    for k, ax in enumerate(axes.upper()):
        c, s = np.cos(a[..., k]), np.sin(a[..., k])
        R = np.zeros(a.shape[:-1] + (3, 3))
        i = "XYZ".index(ax)
        j1, j2 = [m for m in range(3) if m != i]
        R[..., i, i] = 1.0
        R[..., j1, j1] = c
        R[..., j2, j2] = c
        sign = 1.0 if ax != "Y" else -1.0   # right-handed: Ry has +s at (0,2)
        R[..., j1, j2] = -s * sign
        R[..., j2, j1] = s * sign
        out = out @ R
    return out


# Known linear units of motion files; used to guess a BVH's unit from the body size.
CMU_ASF_UNIT_M = 0.0254 / 0.45   # CMU ASF "length 0.45": 1 unit = 1/0.45 inch
KNOWN_UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": CMU_ASF_UNIT_M}


def guess_units_to_metres(clip, typical_height_m=1.7):
    """Pick the known unit that makes the rest skeleton's height closest to a typical adult's."""
    P = clip.rest_positions()
    pts = [P] + [P[j] + e for j, e in clip.end_sites.items()]
    pts = np.vstack([p.reshape(-1, 3) for p in pts])
    ext = np.ptp(pts, axis=0).max()
    if ext <= 0:
        return 1.0
    best = min(KNOWN_UNITS_M.values(), key=lambda u: abs(np.log(ext * u / typical_height_m)))
    return best
