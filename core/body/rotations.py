"""Batched rotation helpers (rotation vectors, axis-angle, matrices) in NumPy."""
import math

import numpy as np


def skew(v):
    """(...,3) -> (...,3,3) cross-product matrices: skew(w) @ v = w x v."""
    v = np.asarray(v, dtype=np.float64)
    if v.shape == (3,):  # one vector: a literal (the local fit calls this per DOF, where overhead dominates)
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def axis_angle_matrix(axis, angle):
    """Rotation by `angle` (...,) about the unit `axis` (3,) or (...,3): Rodrigues' formula."""
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    if angle.ndim == 0 and axis.shape == (3,):  # one rotation: scalar trigonometry, no broadcasting
        k = skew(axis)
        return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
    k = skew(np.broadcast_to(axis, angle.shape + (3,)))
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def rotvec_to_matrix(rotvec):
    """(...,3) rotation vectors (exponential map) -> (...,3,3)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(rotvec, axis=-1)
    safe = np.where(angle > 1e-12, angle, 1.0)
    axis = rotvec / safe[..., None]
    axis = np.where((angle > 1e-12)[..., None], axis, np.array([1.0, 0.0, 0.0]))
    return axis_angle_matrix(axis, angle)


def matrix_to_rotvec(matrix):
    """(...,3,3) -> (...,3) rotation vectors with angle in [0, pi]."""
    m = np.asarray(matrix, dtype=np.float64)
    cos = np.clip((np.trace(m, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    w = np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], axis=-1)
    sin = np.sin(angle)
    small = sin > 1e-6
    out = np.where(small[..., None], w * (angle / np.where(small, 2.0 * sin, 1.0))[..., None], 0.5 * w)
    # Near pi the antisymmetric part vanishes: take the axis from the symmetric part.
    near_pi = (~small) & (angle > 1.0)
    if np.any(near_pi):
        sym = (m[near_pi] + np.eye(3)) / 2.0
        idx = np.argmax(np.diagonal(sym, axis1=-2, axis2=-1), axis=-1)
        axis = sym[np.arange(len(idx)), :, idx]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        out[near_pi] = axis * angle[near_pi][..., None]
    return out


def rotvecs_to_quaternions(rotvecs):
    """(F,3) rotation vectors -> (F,4) unit quaternions (x, y, z, w), each on the side of the previous one."""
    angle = np.linalg.norm(rotvecs, axis=1)
    half = 0.5 * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        axis_scale = np.where(angle > 1e-12, np.sin(half) / angle, 0.5)
    q = np.concatenate([rotvecs * axis_scale[:, None], np.cos(half)[:, None]], axis=1)
    for i in range(1, len(q)):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    return q


def quaternions_to_rotvecs(q, near):
    """(F,4) quaternions -> (F,3) rotation vectors, each the equivalent one (angle or angle - 2 pi) nearest to
    `near` (F,3) (the solved ones, for a smoothed or blended root), so the DOF values stay continuous with them."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(q[:, 3:] < 0, -q, q)  # w >= 0: angle in [0, pi]
    s = np.linalg.norm(q[:, :3], axis=1)
    angle = 2 * np.arctan2(s, q[:, 3])
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(s[:, None] > 1e-12, q[:, :3] / s[:, None], 0.0)
    principal = axis * angle[:, None]
    other = axis * (angle - 2 * np.pi)[:, None]
    closer = np.linalg.norm(other - near, axis=1) < np.linalg.norm(principal - near, axis=1)
    return np.where(closer[:, None], other, principal)


def best_rotation(source, target):
    """The rotation R minimising sum |R source_i - target_i|^2 over two centred point sets (N,3) (Kabsch)."""
    U, _, Vt = np.linalg.svd(target.T @ source)
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt


def orthonormalize(matrix):
    """Nearest rotation (SVD) of (...,3,3)."""
    u, _, vt = np.linalg.svd(matrix)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, -1] *= d[..., None]
    return u @ vt


def rigid_inverse(m):
    """Inverse of (...,4,4) transforms whose 3x3 part is rotation times uniform scale."""
    m = np.asarray(m, dtype=np.float64)
    lin = m[..., :3, :3]
    inv_lin = np.linalg.inv(lin)
    out = np.zeros_like(m)
    out[..., :3, :3] = inv_lin
    out[..., :3, 3] = -(inv_lin @ m[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out
