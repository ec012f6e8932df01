"""The local fit's vertex Jacobian in numba: icp.vertex_jacobian_reference (NumPy, the reference) in one loop.

The NumPy path transforms every vertex by every bone (N x B), sums over a dense bone-ancestry matrix and
walks the bones in Python with small matrix products per DOF; its cost is call overhead (about 2 ms a call,
two calls per local-fit iteration). A vertex has at most a few weighted bones: here each one adds its
transformed position to the lever sums of its ancestors only, and each DOF's column is a cross product per
vertex. Same formulas, so results agree with the reference to rounding (tests/test_icp.py)."""
import math

import numpy as np

from ..body.kinematics_fast import rodrigues
from ..jit import jit


@jit()
def _jacobian_kernel(pose, world, inv_rest, rest_relative, parents, armature, vertices, weights, term_start,
                     term_dof, term_axis, term_share, root_bone, translation_dofs, root_rotation_dofs, J):
    N, B = weights.shape
    # Per vertex and bone: the weighted positions and weights of the bones that bone moves (itself and
    # its descendants), i.e. S = D (w X_s) and Wd = w D^T of the reference.
    S = np.zeros((N, B, 3))
    Wd = np.zeros((N, B))
    for n in range(N):
        vx, vy, vz = vertices[n, 0], vertices[n, 1], vertices[n, 2]
        for s in range(B):
            w = weights[n, s]
            if w == 0.0:
                continue
            # skin_s = world_s @ inv_rest_s applied to the rest vertex
            r0 = inv_rest[s, 0, 0] * vx + inv_rest[s, 0, 1] * vy + inv_rest[s, 0, 2] * vz + inv_rest[s, 0, 3]
            r1 = inv_rest[s, 1, 0] * vx + inv_rest[s, 1, 1] * vy + inv_rest[s, 1, 2] * vz + inv_rest[s, 1, 3]
            r2 = inv_rest[s, 2, 0] * vx + inv_rest[s, 2, 1] * vy + inv_rest[s, 2, 2] * vz + inv_rest[s, 2, 3]
            r3 = inv_rest[s, 3, 0] * vx + inv_rest[s, 3, 1] * vy + inv_rest[s, 3, 2] * vz + inv_rest[s, 3, 3]
            px = world[s, 0, 0] * r0 + world[s, 0, 1] * r1 + world[s, 0, 2] * r2 + world[s, 0, 3] * r3
            py = world[s, 1, 0] * r0 + world[s, 1, 1] * r1 + world[s, 1, 2] * r2 + world[s, 1, 3] * r3
            pz = world[s, 2, 0] * r0 + world[s, 2, 1] * r1 + world[s, 2, 2] * r2 + world[s, 2, 3] * r3
            a = s
            while a >= 0:
                S[n, a, 0] += w * px
                S[n, a, 1] += w * py
                S[n, a, 2] += w * pz
                Wd[n, a] += w
                a = parents[a]
    G = np.empty((4, 4))
    R = np.empty((3, 3))
    acc3 = np.empty((3, 3))
    rot = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for b in range(B):
        if b == root_bone or term_start[b] == term_start[b + 1]:
            continue
        p = parents[b]
        parent_matrix = world[p] if p >= 0 else armature
        for i in range(4):
            for j in range(4):
                G[i, j] = (parent_matrix[i, 0] * rest_relative[b, 0, j]
                           + parent_matrix[i, 1] * rest_relative[b, 1, j]
                           + parent_matrix[i, 2] * rest_relative[b, 2, j]
                           + parent_matrix[i, 3] * rest_relative[b, 3, j])
        det = (G[0, 0] * (G[1, 1] * G[2, 2] - G[1, 2] * G[2, 1])
               - G[0, 1] * (G[1, 0] * G[2, 2] - G[1, 2] * G[2, 0])
               + G[0, 2] * (G[1, 0] * G[2, 1] - G[1, 1] * G[2, 0]))
        cube_root = math.copysign(abs(det) ** (1.0 / 3.0), det)  # drop a uniform object scale
        for i in range(3):
            for j in range(3):
                R[i, j] = G[i, j] / cube_root
                acc3[i, j] = 1.0 if i == j else 0.0
        qx, qy, qz = G[0, 3], G[1, 3], G[2, 3]
        for k in range(term_start[b], term_start[b + 1]):
            ax, ay, az = term_axis[k, 0], term_axis[k, 1], term_axis[k, 2]
            # w = R (acc axis), normalised
            cx = acc3[0, 0] * ax + acc3[0, 1] * ay + acc3[0, 2] * az
            cy = acc3[1, 0] * ax + acc3[1, 1] * ay + acc3[1, 2] * az
            cz = acc3[2, 0] * ax + acc3[2, 1] * ay + acc3[2, 2] * az
            wx = R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
            wy = R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
            wz = R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz
            norm = math.sqrt(wx * wx + wy * wy + wz * wz)
            share = term_share[k]
            wx, wy, wz = share * wx / norm, share * wy / norm, share * wz / norm
            d = term_dof[k]
            for n in range(N):
                lx = S[n, b, 0] - Wd[n, b] * qx
                ly = S[n, b, 1] - Wd[n, b] * qy
                lz = S[n, b, 2] - Wd[n, b] * qz
                J[n, 0, d] += wy * lz - wz * ly
                J[n, 1, d] += wz * lx - wx * lz
                J[n, 2, d] += wx * ly - wy * lx
            rodrigues(ax, ay, az, pose[d] * share, rot)
            for i in range(3):
                for j in range(3):
                    tmp[i, j] = acc3[i, 0] * rot[0, j] + acc3[i, 1] * rot[1, j] + acc3[i, 2] * rot[2, j]
            acc3[:, :] = tmp
    r = root_bone
    for n in range(N):
        for t in range(translation_dofs.shape[0]):
            for i in range(3):
                J[n, i, translation_dofs[t]] = Wd[n, r] if i == t else 0.0
        lx = S[n, r, 0] - Wd[n, r] * world[r, 0, 3]
        ly = S[n, r, 1] - Wd[n, r] * world[r, 1, 3]
        lz = S[n, r, 2] - Wd[n, r] * world[r, 2, 3]
        # e_k x lever for the world axes k = x, y, z
        J[n, 0, root_rotation_dofs[0]], J[n, 1, root_rotation_dofs[0]], J[n, 2, root_rotation_dofs[0]] = 0.0, -lz, ly
        J[n, 0, root_rotation_dofs[1]], J[n, 1, root_rotation_dofs[1]], J[n, 2, root_rotation_dofs[1]] = lz, 0.0, -lx
        J[n, 0, root_rotation_dofs[2]], J[n, 1, root_rotation_dofs[2]], J[n, 2, root_rotation_dofs[2]] = -ly, lx, 0.0


def vertex_jacobian(body, pose_abs, rest_vertices, weights):
    """icp.vertex_jacobian_reference's (N,3,D) in one compiled pass."""
    sk = body.skeleton
    x = np.ascontiguousarray(pose_abs, dtype=np.float64).reshape(-1)
    world = body.pose_matrices(x[None])[0]
    vertices = np.ascontiguousarray(rest_vertices, dtype=np.float64)
    J = np.zeros((len(vertices), 3, body.n_dof))
    _jacobian_kernel(x, np.ascontiguousarray(world), np.ascontiguousarray(sk.inv_rest),
                     np.ascontiguousarray(sk.rest_relative), sk.parents.astype(np.int64),
                     np.ascontiguousarray(sk.armature_matrix, dtype=np.float64), vertices,
                     np.ascontiguousarray(weights, dtype=np.float64), body._term_start, body._term_dof,
                     body._term_axis, body._term_share, int(body.root_bone),
                     np.asarray(body.translation_dofs, dtype=np.int64),
                     np.asarray(body.root_rotation_dofs, dtype=np.int64), J)
    return J
