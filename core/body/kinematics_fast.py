"""Forward kinematics in numba: Body.pose_matrices' NumPy path (the reference) in one compiled loop.

The NumPy path builds every DOF's rotation for the whole batch, then walks the bones with batched 4x4
products; its cost is mostly call overhead and temporaries (about 1 ms a call, some 40 calls a frame, half of
them for one pose in the local fit). Here each pose walks the chain once with its matrices in registers and
cache. Same formulas (Rodrigues, the bones' rotations multiplied in the same order), so results agree with
the reference to rounding (tests/test_body.py)."""
import math

import numpy as np

from ..jit import jit


@jit()
def _matmul4(a, b, out):
    for i in range(4):
        a0, a1, a2, a3 = a[i, 0], a[i, 1], a[i, 2], a[i, 3]
        for j in range(4):
            out[i, j] = a0 * b[0, j] + a1 * b[1, j] + a2 * b[2, j] + a3 * b[3, j]


@jit()
def rodrigues(x, y, z, angle, rot):
    """rot (3,3) <- the rotation by `angle` about the unit axis (x, y, z): I + sin K + (1 - cos) K^2, with
    K^2 = a a^T - (a.a) I."""
    s, c1 = math.sin(angle), 1.0 - math.cos(angle)
    aa = x * x + y * y + z * z
    rot[0, 0] = 1.0 + c1 * (x * x - aa)
    rot[1, 1] = 1.0 + c1 * (y * y - aa)
    rot[2, 2] = 1.0 + c1 * (z * z - aa)
    rot[0, 1] = -s * z + c1 * x * y
    rot[1, 0] = s * z + c1 * x * y
    rot[0, 2] = s * y + c1 * x * z
    rot[2, 0] = -s * y + c1 * x * z
    rot[1, 2] = -s * x + c1 * y * z
    rot[2, 1] = s * x + c1 * y * z


@jit()
def _chain_kernel(poses, term_axis, term_dof, term_share, term_start, root_basis, root_bone, order, parents,
                  rest_relative, armature, world, out):
    P = poses.shape[0]
    basis = np.empty((4, 4))
    rot = np.empty((3, 3))
    tmp = np.empty((3, 3))
    local = np.empty((4, 4))
    for p in range(P):
        for bi in range(order.shape[0]):
            b = order[bi]
            if b == root_bone:
                basis[:, :] = root_basis[p]
            else:
                basis[:, :] = 0.0
                for i in range(4):
                    basis[i, i] = 1.0
                for k in range(term_start[b], term_start[b + 1]):
                    rodrigues(term_axis[k, 0], term_axis[k, 1], term_axis[k, 2],
                              poses[p, term_dof[k]] * term_share[k], rot)
                    for i in range(3):
                        for j in range(3):
                            tmp[i, j] = basis[i, 0] * rot[0, j] + basis[i, 1] * rot[1, j] + basis[i, 2] * rot[2, j]
                    basis[:3, :3] = tmp
            _matmul4(rest_relative[b], basis, local)
            parent = parents[b]
            if parent < 0:
                out[p, b] = local
            else:
                _matmul4(out[p, parent], local, out[p, b])
        if world:
            for b in range(out.shape[1]):
                basis[:, :] = out[p, b]
                _matmul4(armature, basis, out[p, b])


def pose_matrices(body, poses, root_basis, world):
    """(P,D) poses with their root bases (P,4,4) -> (P,B,4,4), as Body.pose_matrices."""
    P, B = poses.shape[0], body.skeleton.n_bones
    out = np.empty((P, B, 4, 4))
    sk = body.skeleton
    _chain_kernel(poses, body._term_axis, body._term_dof, body._term_share, body._term_start,
                  np.ascontiguousarray(root_basis), body.root_bone, sk.order, sk.parents,
                  np.ascontiguousarray(sk.rest_relative), np.ascontiguousarray(sk.armature_matrix), bool(world), out)
    return out
