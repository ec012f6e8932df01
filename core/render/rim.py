"""Silhouette-rim vertices of a posed mesh in one camera (the model side of ICP, algorithms.md 6).

A rim (contour-generator) edge is shared by a triangle facing the camera and one facing away; its
vertices project onto the outline of the mesh. Of those we keep the ones that are visible (no
other surface in front of them, checked against a z-buffer of the mesh) and, by default, that lie
on the *outer* projected silhouette, because a silhouette image only shows the outer outline: the
rim of an arm in front of the torso has no counterpart in it.

Each kept vertex gets an outward 2-D normal of the projected outline. Where the surface folds,
the front and back triangles of a rim edge project onto the same side of the edge, so the third
corner of the front triangle marks the inside.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .reference import bounding_box_pixels

Z_NEAR = 1e-3  # metres: triangles with a corner closer to the camera plane are not drawn


class RimInputError(ValueError):
    """Mesh arrays handed to the rim finder have the wrong shape or contents."""


@dataclass
class MeshEdges:
    """Edge/triangle incidence of a fixed triangle list (computed once per mesh).

    Every triangle contributes three incidences (edge id, triangle, third corner).
    """

    edges: np.ndarray  # (E,2) vertex ids, smaller first
    incidence_edge: np.ndarray  # (3F,) edge id of each (triangle, side)
    incidence_face: np.ndarray  # (3F,) triangle of each incidence
    incidence_opposite: np.ndarray  # (3F,) the triangle's corner not on that edge

    @classmethod
    def from_faces(cls, faces) -> "MeshEdges":
        faces = np.asarray(faces, dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise RimInputError(f"faces must have shape (F, 3) (triangles); got {faces.shape}")
        F = len(faces)
        pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])  # side k of every face
        opposite = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
        pairs = np.sort(pairs, axis=1)
        edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
        face_of = np.tile(np.arange(F), 3)
        return cls(edges, inverse.reshape(-1), face_of, opposite)

    @property
    def n_edges(self) -> int:
        return len(self.edges)


@dataclass
class Rim:
    """Rim vertices of one view: ids into the mesh, pixels, camera depth and outward 2-D unit normals."""

    vertex: np.ndarray  # (N,) int
    uv: np.ndarray  # (N,2)
    depth: np.ndarray  # (N,)
    normal: np.ndarray  # (N,2)

    def __len__(self):
        return len(self.vertex)


def front_facing(vertices, faces, camera_center) -> np.ndarray:
    """(F,) True where the triangle's winding normal points towards the camera centre."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    n = np.cross(b - a, c - a)
    return np.einsum("fi,fi->f", n, np.asarray(camera_center, dtype=np.float64) - a) > 0


def _pixel_samples(uv, z, faces, width, height):
    """Every (pixel centre, triangle) pair with the centre inside the triangle.

    Returns flat pixel ids, triangle ids and the barycentric weights (wa, wb, wc). Candidates are all
    pixels in each triangle's bounding box, tested at once; a centre on a shared edge counts for both.
    """
    uv = np.asarray(uv, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    empty = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0))
    if len(faces) == 0:
        return empty
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    xs = np.stack([a[:, 0], b[:, 0], c[:, 0]], axis=1)
    ys = np.stack([a[:, 1], b[:, 1], c[:, 1]], axis=1)
    with np.errstate(invalid="ignore"):
        x0 = np.maximum(np.ceil(np.clip(xs.min(1), -1.0, width)), 0).astype(np.int64)
        x1 = np.minimum(np.floor(np.clip(xs.max(1), -1.0, width)), width - 1).astype(np.int64)
        y0 = np.maximum(np.ceil(np.clip(ys.min(1), -1.0, height)), 0).astype(np.int64)
        y1 = np.minimum(np.floor(np.clip(ys.max(1), -1.0, height)), height - 1).astype(np.int64)
    ok = (z[faces].min(1) > Z_NEAR) & (area != 0) & np.isfinite(area) & (x1 >= x0) & (y1 >= y0)
    tri = np.nonzero(ok)[0]
    if tri.size == 0:
        return empty
    t, px, py = bounding_box_pixels(tri, x0, x1, y0, y1)
    fx, fy = px.astype(np.float64), py.astype(np.float64)
    # Barycentric weights (signed areas / total area): all >= 0 inside, whatever the winding.
    s = 1.0 / area[t]
    wa = ((b[t, 0] - fx) * (c[t, 1] - fy) - (b[t, 1] - fy) * (c[t, 0] - fx)) * s
    wb = ((c[t, 0] - fx) * (a[t, 1] - fy) - (c[t, 1] - fy) * (a[t, 0] - fx)) * s
    wc = 1.0 - wa - wb
    inside = (wa >= 0) & (wb >= 0) & (wc >= 0)
    return (py * width + px)[inside], t[inside], np.stack([wa[inside], wb[inside], wc[inside]])


def depth_buffer(uv, z, faces, width, height) -> np.ndarray:
    """(H,W) depth of the nearest surface at every pixel centre (inf where nothing is drawn).

    Pixel (row i, column j) is sampled at (x=j, y=i); depth is interpolated as 1/z (exact under
    perspective for planar triangles).
    """
    pixel, t, w = _pixel_samples(uv, z, faces, width, height)
    inv_depth = np.zeros(height * width)
    if pixel.size:
        zf = np.asarray(z, dtype=np.float64)[np.asarray(faces, dtype=np.int64)[t]]
        np.maximum.at(inv_depth, pixel, w[0] / zf[:, 0] + w[1] / zf[:, 1] + w[2] / zf[:, 2])
    with np.errstate(divide="ignore"):
        depth = np.where(inv_depth > 0, 1.0 / np.where(inv_depth > 0, inv_depth, 1.0), np.inf)
    return depth.reshape(height, width)


def coverage(uv, z, faces, width, height) -> np.ndarray:
    """(H,W) bool: pixel centres covered by the mesh (what depth_buffer draws, without depths)."""
    mask = np.zeros(height * width, dtype=bool)
    mask[_pixel_samples(uv, z, faces, width, height)[0]] = True
    return mask.reshape(height, width)


def _coverage(uv, z, faces, width, height):
    """`coverage`, by the numba kernel when numba is there (render/fast.py; the same tests)."""
    try:
        from .fast import coverage as fast_coverage
    except ImportError:
        return coverage(uv, z, faces, width, height)
    return fast_coverage(uv, z, faces, width, height)


def _window_any(image, radius, row, col):
    """Whether `image` is set anywhere in the (2r+1)^2 window around each (row, col), edge-padded:
    `_window_extreme(image, radius, np.logical_or)[row, col]` without the whole image."""
    H, W = image.shape
    out = np.zeros(len(row), dtype=bool)
    for dy in range(-radius, radius + 1):
        rows = np.clip(row + dy, 0, H - 1)
        for dx in range(-radius, radius + 1):
            out |= image[rows, np.clip(col + dx, 0, W - 1)]
    return out


def _window_extreme(image, radius, reduce):
    """Max or min of `image` over the (2r+1)^2 window around every pixel (edge-padded)."""
    padded = np.pad(image, radius, mode="edge")
    H, W = image.shape
    out = padded[radius:radius + H, radius:radius + W].copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            reduce(out, padded[radius + dy:radius + dy + H, radius + dx:radius + dx + W], out=out)
    return out


def rim_edges(vertices, faces, edges: MeshEdges, camera_center) -> tuple[np.ndarray, np.ndarray]:
    """Edge mask (E,) of rim edges and the front-facing flag of every triangle (F,).

    An edge is on the rim when at least one adjacent triangle faces the camera and at least one
    faces away; open boundary edges (one triangle) never are.
    """
    front = front_facing(vertices, faces, camera_center)
    f_inc = front[edges.incidence_face]
    n_front = np.bincount(edges.incidence_edge, weights=f_inc, minlength=edges.n_edges)
    n_back = np.bincount(edges.incidence_edge, weights=~f_inc, minlength=edges.n_edges)
    return (n_front > 0) & (n_back > 0), front


def rim_vertices(vertices, faces, camera, edges: MeshEdges | None = None, *, depth=None,
                 depth_tolerance: float = 0.03, outer_only: bool = True, window: int = 1) -> Rim:
    """Visible rim vertices of the mesh `vertices` (V,3 world) in `camera` (at the energy resolution).

    depth: a z-buffer from `depth_buffer` for this view (computed here when None; with outer_only
    only its background matters, so `coverage` stands in for it).
    Visibility is judged in the (2w+1)^2 pixel window around the vertex's projection:
    * a background pixel there means the vertex sits on the outer outline, where nothing covers it
      (the surface's own front side, right next to a rim, is far nearer than the rim itself, so a
      plain depth comparison would wrongly hide it);
    * otherwise it is visible when it is no deeper than the farthest drawn surface in the window
      plus `depth_tolerance` (metres): a surface in front of all its neighbouring pixels hides it.
    outer_only keeps only the first kind (the default: a silhouette image shows only the outer outline).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise RimInputError(f"vertices must have shape (V, 3); got {vertices.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise RimInputError(f"faces index vertices outside 0..{len(vertices) - 1}: pass the mesh's own faces")
    edges = MeshEdges.from_faces(faces) if edges is None else edges
    W, H = camera.width, camera.height
    uv, z = camera.project_with_depth(vertices)
    if depth is None:  # the outer outline needs only the coverage, which is cheaper
        depth = np.where(_coverage(uv, z, faces, W, H), 0.0, np.inf) if outer_only else depth_buffer(uv, z, faces, W, H)
    rim, front = rim_edges(vertices, faces, edges, camera.center)

    # Outward normals: perpendicular of each rim edge, pointing away from its front triangle's third corner.
    inc = rim[edges.incidence_edge] & front[edges.incidence_face]
    e = edges.edges[edges.incidence_edge[inc]]
    d = uv[e[:, 1]] - uv[e[:, 0]]
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)  # length = edge length: longer edges weigh more
    inward = uv[edges.incidence_opposite[inc]] - uv[e[:, 0]]
    n *= np.where(np.einsum("ni,ni->n", n, inward) > 0, -1.0, 1.0)[:, None]
    ends = np.concatenate([e[:, 0], e[:, 1]])  # each edge's normal goes to both its vertices (bincount: add.at is slow)
    acc = np.stack([np.bincount(ends, weights=np.tile(n[:, k], 2), minlength=len(vertices)) for k in range(2)], axis=1)

    ids = np.unique(edges.edges[rim])
    norm = np.linalg.norm(acc[ids], axis=1)
    u = uv[ids]
    with np.errstate(invalid="ignore"):
        col, row = np.rint(u[:, 0]), np.rint(u[:, 1])
    keep = (z[ids] > Z_NEAR) & (norm > 0) & (col >= 0) & (col < W) & (row >= 0) & (row < H)
    ids, norm, u, col, row = ids[keep], norm[keep], u[keep], col[keep].astype(np.int64), row[keep].astype(np.int64)
    background = np.isinf(depth)
    open_sky = _window_any(background, window, row, col)
    if outer_only:
        visible = open_sky
    else:
        farthest = _window_extreme(np.where(background, -np.inf, depth), window, np.maximum)[row, col]
        visible = (z[ids] <= farthest + depth_tolerance) | open_sky
    ids = ids[visible]
    return Rim(ids, uv[ids], z[ids], acc[ids] / norm[visible][:, None])
