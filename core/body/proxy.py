"""The proxy mesh the likelihood renders: the skinned mesh simplified to about 2000 triangles.

Vertex clustering on a grid, done separately per body part so that touching limbs (thighs, arms
against the torso) are never welded together. Each cluster becomes one vertex at the mean rest
position with the mean skin weights; triangles whose corners fall into fewer than three clusters
vanish. The grid size is found by bisection to hit the requested triangle count.
Each triangle is labelled with its body part (the part holding most of its skin weight).
"""
from dataclasses import dataclass

import numpy as np


@dataclass
class ProxyMesh:
    vertices: np.ndarray  # (V,3) rest, armature space
    weights: np.ndarray  # (V,B) normalised
    unweighted: np.ndarray  # (V,) bool
    faces: np.ndarray  # (F,3)
    face_part: np.ndarray  # (F,) body part index
    vertex_part: np.ndarray  # (V,)
    part_names: list
    part_area_share: np.ndarray  # (n_parts,) rest surface area share of each part (colour term w_s)

    def deform(self, body, poses, root_anchor=None):
        return body.deform(poses, root_anchor, self.vertices, self.weights, self.unweighted)


def vertex_parts(body, weights):
    part_weights = np.zeros((len(weights), len(body.part_names)))
    np.add.at(part_weights.T, body.bone_part, weights.T)
    return np.argmax(part_weights, axis=1), part_weights


def _cluster(vertices, parts, cell):
    keys = np.concatenate([parts[:, None], np.floor(vertices / cell).astype(np.int64)], axis=1)
    _, labels = np.unique(keys, axis=0, return_inverse=True)
    return labels.reshape(-1)


def _collapse_faces(faces, labels):
    f = labels[faces]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    f = f[keep]
    # Drop duplicates regardless of winding order.
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    return f[np.sort(first)]


def triangle_areas(vertices, faces):
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def make_proxy(body, target_triangles=2000):
    """Simplify body's mesh to about `target_triangles` (within 10%, or the full mesh if smaller)."""
    verts, faces, weights = body.vertices, body.faces, body.weights
    parts, _ = vertex_parts(body, weights)
    if len(faces) <= target_triangles:
        labels = np.arange(len(verts))
    else:
        extent = np.ptp(verts, axis=0).max()
        lo, hi = extent * 1e-4, extent * 0.2
        labels, best_n = None, None
        for _ in range(40):
            cell = np.sqrt(lo * hi)
            trial = _cluster(verts, parts, cell)
            n = len(_collapse_faces(faces, trial))
            if labels is None or abs(n - target_triangles) < abs(best_n - target_triangles):
                labels, best_n = trial, n
            if abs(n - target_triangles) <= 0.02 * target_triangles:
                break
            if n > target_triangles:
                lo = cell
            else:
                hi = cell
    n_clusters = labels.max() + 1
    counts = np.bincount(labels, minlength=n_clusters).astype(np.float64)
    new_verts = np.zeros((n_clusters, 3))
    np.add.at(new_verts, labels, verts)
    new_verts /= counts[:, None]
    new_weights = np.zeros((n_clusters, weights.shape[1]))
    np.add.at(new_weights, labels, weights)
    total = new_weights.sum(axis=1, keepdims=True)
    new_weights = np.divide(new_weights, total, out=np.zeros_like(new_weights), where=total > 0)
    new_faces = _collapse_faces(faces, labels)
    v_part, part_w = vertex_parts(body, new_weights)
    face_part_w = part_w[new_faces].sum(axis=1)
    face_part = np.argmax(face_part_w, axis=1)
    areas = triangle_areas(new_verts, new_faces)
    part_area = np.bincount(face_part, weights=areas, minlength=len(body.part_names))
    return ProxyMesh(new_verts, new_weights, total[:, 0] <= 0, new_faces, face_part, v_part,
                     list(body.part_names), part_area / part_area.sum())
