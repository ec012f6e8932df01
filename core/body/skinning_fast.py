"""Linear blend skinning in numba: the sum of body.blend_vertices (the NumPy reference) taken over each
vertex's non-zero weights only (about 3 of the 31 bones for the proxy), parallel over poses.

The reference multiplies the dense (V,B) weights with every pose's matrices in one GEMM; most of those
products are by zero weights, and the GEMM plus its (V,P,3,4) temporary cost more than the rasteriser's
projection of the same vertices."""
import numpy as np
from numba import prange

from ..jit import jit


@jit(parallel=True)
def _blend_kernel(M, vertices, start, bone, weight, out):
    P, V = out.shape[0], out.shape[1]
    for p in prange(P):
        for v in range(V):
            x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
            for i in range(3):
                a0 = a1 = a2 = a3 = 0.0
                for k in range(start[v], start[v + 1]):
                    b, w = bone[k], weight[k]
                    a0 += w * M[p, b, i, 0]
                    a1 += w * M[p, b, i, 1]
                    a2 += w * M[p, b, i, 2]
                    a3 += w * M[p, b, i, 3]
                out[p, v, i] = a0 * x + a1 * y + a2 * z + a3


def blend_vertices(skin_matrices, vertices, weights, unweighted, armature_matrix):
    """Same arguments and result as core.body.model.blend_vertices: (P,B,4,4) skinning matrices -> (P,V,3)."""
    rows, cols = np.nonzero(weights)  # row-major: each vertex's bones in order
    start = np.searchsorted(rows, np.arange(len(vertices) + 1)).astype(np.int64)
    out = np.empty((skin_matrices.shape[0], len(vertices), 3))
    _blend_kernel(np.ascontiguousarray(skin_matrices, dtype=np.float64),
                  np.ascontiguousarray(vertices, dtype=np.float64), start, cols.astype(np.int64),
                  np.ascontiguousarray(weights[rows, cols], dtype=np.float64), out)
    if unweighted is not None and np.any(unweighted):
        out[:, unweighted] = vertices[unweighted] @ armature_matrix[:3, :3].T + armature_matrix[:3, 3]
    return out
