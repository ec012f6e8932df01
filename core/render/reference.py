"""The reference rasteriser and likelihood statistics: plain NumPy, written to be obviously right.

Everything the fast path (fast.py) computes is defined here first; tests compare the two.

Rasterisation rules (shared bit for bit with fast.py):
* pixel (row i, column j) is sampled at its centre, the point (x=j, y=i) of the camera's pixel
  coordinates (OpenCV: (0, 0) is the centre of the top-left pixel);
* a triangle is the projection of its three (distorted) vertices joined by straight edges; it is
  skipped if any vertex lies closer than Z_NEAR to the camera plane or if it has zero area;
* a pixel centre is inside when all three edge functions are positive, or zero on an edge the
  top-left rule gives to the triangle (so two triangles sharing an edge never both own a pixel);
* depth test on interpolated 1/z (exact for planar triangles under perspective); ties keep the
  triangle drawn first (lowest index);
* label image: 0 = background, part index + 1 on the body;
* boundary (eq. 9 / A10): body pixels with an in-image 4-neighbour of another label (background
  counts as a label; the image border does not make a boundary).

Statistics of one pose in one view (columns of the (P, C, N_STATS) array), against a prepared frame
(`FrameTargets`, everything at the energy resolution):
  TEMPLATE      #template pixels
  OVERLAP       #(template AND observed silhouette)      -> XOR = TEMPLATE + #observed - 2 OVERLAP
  SUM_DI        sum of the observed silhouette's distance map over template pixels (eq. 7b, 1st sum)
  SUM_DT        sum of the template's 3-4 chamfer distance (pixels) over observed pixels (7b, 2nd sum)
  BOUNDARY      #template boundary pixels
  BOUNDARY_OFF  #boundary pixels not on an image edge (sum of E_v, E = 0 on edges, eq. 9)
  SUM_EDGE_DT   sum of the truncated edge distance map over boundary pixels (e^Ch)
plus, with colour on, per-part a/b histograms of the visible body pixels (P, C, S, 2, K).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Z_NEAR = 1e-3  # metres: triangles with a vertex closer to the camera plane are not drawn
N_BINS = 64  # colour histogram bins per channel (eq. 10, K = 64)

TEMPLATE, OVERLAP, SUM_DI, SUM_DT, BOUNDARY, BOUNDARY_OFF, SUM_EDGE_DT = range(7)
N_STATS = 7


class RenderInputError(ValueError):
    """Arrays handed to the rasteriser have the wrong shape or contents."""


@dataclass
class FrameTargets:
    """The observed side of one frame, per view, padded to the largest view (H, W).

    widths/heights give each view's real size; pixels outside it are zero and never read.
    """

    widths: np.ndarray  # (C,) int64
    heights: np.ndarray  # (C,) int64
    silhouette: np.ndarray  # (C,H,W) uint8, 1 on the observed subject
    silhouette_dt: np.ndarray  # (C,H,W) float64, distance to the observed silhouette (energy pixels)
    edge_off: np.ndarray  # (C,H,W) uint8, E_v: 0 on image edges, 1 elsewhere
    edge_dt: np.ndarray  # (C,H,W) float64, truncated distance to the nearest image edge (energy pixels)
    ab_bins: np.ndarray  # (C,H,W,2) uint8, histogram bin of the diffused a and b channels

    def __post_init__(self):
        self.widths = np.asarray(self.widths, dtype=np.int64)
        self.heights = np.asarray(self.heights, dtype=np.int64)
        self.silhouette = np.ascontiguousarray(self.silhouette, dtype=np.uint8)
        self.silhouette_dt = np.ascontiguousarray(self.silhouette_dt, dtype=np.float64)
        self.edge_off = np.ascontiguousarray(self.edge_off, dtype=np.uint8)
        self.edge_dt = np.ascontiguousarray(self.edge_dt, dtype=np.float64)
        self.ab_bins = np.ascontiguousarray(self.ab_bins, dtype=np.uint8)
        C, H, W = self.silhouette.shape
        for name in ("silhouette_dt", "edge_off", "edge_dt"):
            if getattr(self, name).shape != (C, H, W):
                raise RenderInputError(f"FrameTargets.{name} has shape {getattr(self, name).shape}; "
                                       f"expected {(C, H, W)} like the silhouettes")
        if self.ab_bins.shape != (C, H, W, 2):
            raise RenderInputError(f"FrameTargets.ab_bins has shape {self.ab_bins.shape}; expected {(C, H, W, 2)}")
        if len(self.widths) != C or len(self.heights) != C or np.any(self.widths > W) or np.any(self.heights > H):
            raise RenderInputError("FrameTargets: one width and height per view, each within the padded size")
        self.observed_count = np.array([int(self.silhouette[c].sum()) for c in range(C)], dtype=np.int64)
        box = np.zeros((C, 4), dtype=np.int64)  # y0, y1, x0, x1 inclusive; y1 < y0 when empty
        box[:, 1] = -1
        for c in range(C):
            ys, xs = np.nonzero(self.silhouette[c])
            if ys.size:
                box[c] = ys.min(), ys.max(), xs.min(), xs.max()
        self.observed_box = box

    @property
    def n_views(self):
        return len(self.widths)


def ab_to_bins(ab):
    """CIELab a or b (native units, about -128..127) -> histogram bin, floor((v + 128) * K / 256) in [0, K)."""
    return np.clip(np.floor((np.asarray(ab, dtype=np.float64) + 128.0) * (N_BINS / 256.0)), 0, N_BINS - 1).astype(
        np.uint8)


def project_views(vertices, cameras):
    """(P,V,3) world vertices -> pixels (P,C,V,2) and camera depths (P,C,V) in every camera."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 3 or vertices.shape[2] != 3:
        raise RenderInputError(f"vertices must have shape (poses, vertices, 3); got {vertices.shape}")
    P, V = vertices.shape[:2]
    uv = np.empty((P, len(cameras), V, 2))
    z = np.empty((P, len(cameras), V))
    for c, cam in enumerate(cameras):
        uv[:, c], z[:, c] = cam.project_with_depth(vertices)
    return uv, z


def _edge(ax, ay, bx, by, px, py):
    # Same expression, same operation order as fast.py: results agree to the last bit.
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


def _owns_zero_edge(ax, ay, bx, by):
    """Top-left rule for an edge a->b of a positively oriented triangle (y pointing down)."""
    dx, dy = bx - ax, by - ay
    return (dy < 0) | ((dy == 0) & (dx > 0))


def rasterize(uv, z, faces, face_label, width, height, cull=0):
    """One mesh in one view -> label image (H,W) int16 (0 background, face_label elsewhere).

    cull: 0 draws every triangle; +1 / -1 draws only triangles of positive / negative signed image
    area (back-face culling for a closed mesh whose front faces have that sign; see `front_sign`).

    All (triangle, pixel-centre) candidates inside each triangle's bounding box are tested at once;
    the z-buffer keeps, per pixel, the largest 1/z and among equals the lowest triangle index.
    """
    uv = np.asarray(uv, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    labels = np.zeros((height, width), dtype=np.int16)
    if len(faces) == 0:
        return labels
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    za, zb, zc = z[faces[:, 0]], z[faces[:, 1]], z[faces[:, 2]]
    area = _edge(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])
    facing = cull * area >= 0
    flip = area < 0  # make every triangle positively oriented: swap b and c
    b2 = np.where(flip[:, None], c, b)
    c2 = np.where(flip[:, None], b, c)
    zb2 = np.where(flip, zc, zb)
    zc2 = np.where(flip, zb, zc)
    b, c, zb, zc, area = b2, c2, zb2, zc2, np.abs(area)
    xs = np.stack([a[:, 0], b[:, 0], c[:, 0]], axis=1)
    ys = np.stack([a[:, 1], b[:, 1], c[:, 1]], axis=1)
    with np.errstate(invalid="ignore"):
        x0 = np.ceil(np.clip(xs.min(axis=1), -1.0, width)).astype(np.int64)
        x1 = np.floor(np.clip(xs.max(axis=1), -1.0, width)).astype(np.int64)
        y0 = np.ceil(np.clip(ys.min(axis=1), -1.0, height)).astype(np.int64)
        y1 = np.floor(np.clip(ys.max(axis=1), -1.0, height)).astype(np.int64)
    x0, y0 = np.maximum(x0, 0), np.maximum(y0, 0)
    x1, y1 = np.minimum(x1, width - 1), np.minimum(y1, height - 1)
    ok = facing & (np.minimum(np.minimum(za, zb), zc) > Z_NEAR) & (area > 0) & np.isfinite(area) & (x1 >= x0) & (y1 >= y0)
    tri = np.nonzero(ok)[0]
    if tri.size == 0:
        return labels
    nx, ny = x1[tri] - x0[tri] + 1, y1[tri] - y0[tri] + 1
    counts = nx * ny
    t = np.repeat(tri, counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    nxt = np.repeat(nx, counts)
    px = (x0[t] + local % nxt).astype(np.float64)
    py = (y0[t] + local // nxt).astype(np.float64)
    ax_, ay_, bx_, by_, cx_, cy_ = a[t, 0], a[t, 1], b[t, 0], b[t, 1], c[t, 0], c[t, 1]
    w0 = _edge(bx_, by_, cx_, cy_, px, py)  # weight of a
    w1 = _edge(cx_, cy_, ax_, ay_, px, py)  # weight of b
    w2 = _edge(ax_, ay_, bx_, by_, px, py)  # weight of c
    inside = (((w0 > 0) | ((w0 == 0) & _owns_zero_edge(bx_, by_, cx_, cy_)))
              & ((w1 > 0) | ((w1 == 0) & _owns_zero_edge(cx_, cy_, ax_, ay_)))
              & ((w2 > 0) | ((w2 == 0) & _owns_zero_edge(ax_, ay_, bx_, by_))))
    t, px, py = t[inside], px[inside].astype(np.int64), py[inside].astype(np.int64)
    w0, w1, w2 = w0[inside], w1[inside], w2[inside]
    inv_z = (w0 * (1.0 / za[t]) + w1 * (1.0 / zb[t]) + w2 * (1.0 / zc[t])) * (1.0 / area[t])
    pixel = py * width + px
    order = np.lexsort((t, -inv_z, pixel))  # per pixel: nearest first, then lowest triangle index
    pixel, t = pixel[order], t[order]
    first = np.ones(pixel.size, dtype=bool)
    first[1:] = pixel[1:] != pixel[:-1]
    labels.reshape(-1)[pixel[first]] = np.asarray(face_label)[t[first]]
    return labels


def boundary_mask(labels):
    """Body pixels whose up/down/left/right in-image neighbour carries another label."""
    lab = np.asarray(labels)
    diff = np.zeros(lab.shape, dtype=bool)
    vertical = lab[1:] != lab[:-1]
    horizontal = lab[:, 1:] != lab[:, :-1]
    diff[1:] |= vertical
    diff[:-1] |= vertical
    diff[:, 1:] |= horizontal
    diff[:, :-1] |= horizontal
    return diff & (lab > 0)


def chamfer_34(mask):
    """Borgefors 3-4 chamfer distance (in pixels, i.e. units / 3) from every pixel to the nearest True one.

    Two raster passes. Within a row the left-to-right dependency d[j] = min(d[j], d[j-1] + 3) is a
    running minimum of d[k] - 3k, so each row is one vectorised step. Without True pixels every
    distance is infinite.
    """
    m = np.asarray(mask, dtype=bool)
    H, W = m.shape
    big = np.iinfo(np.int64).max // 4
    d = np.where(m, 0, big).astype(np.int64)
    ramp = 3 * np.arange(W, dtype=np.int64)
    for i in range(H):  # forward: neighbours above, then the left one
        row = d[i]
        if i > 0:
            up = d[i - 1]
            row = np.minimum(row, up + 3)
            row[1:] = np.minimum(row[1:], up[:-1] + 4)
            row[:-1] = np.minimum(row[:-1], up[1:] + 4)
        d[i] = ramp + np.minimum.accumulate(row - ramp)
    for i in range(H - 1, -1, -1):  # backward: neighbours below, then the right one
        row = d[i]
        if i < H - 1:
            down = d[i + 1]
            row = np.minimum(row, down + 3)
            row[1:] = np.minimum(row[1:], down[:-1] + 4)
            row[:-1] = np.minimum(row[:-1], down[1:] + 4)
        d[i] = (np.minimum.accumulate((row + ramp)[::-1]))[::-1] - ramp
    out = d / 3.0
    out[d >= big // 2] = np.inf
    return out


def render_view(uv, z, faces, face_label, width, height, cull=0):
    """(labels, silhouette, boundary) of one mesh in one view."""
    labels = rasterize(uv, z, faces, face_label, width, height, cull)
    return labels, labels > 0, boundary_mask(labels)


def view_statistics(labels, targets: FrameTargets, view, need_chamfer=True, n_parts=0):
    """The statistics row (N_STATS,) and part histograms (n_parts, 2, K) of one label image."""
    h, w = int(targets.heights[view]), int(targets.widths[view])
    labels = np.asarray(labels)[:h, :w]
    sil = labels > 0
    obs = targets.silhouette[view, :h, :w] > 0
    boundary = boundary_mask(labels)
    stats = np.zeros(N_STATS)
    stats[TEMPLATE] = sil.sum()
    stats[OVERLAP] = (sil & obs).sum()
    stats[SUM_DI] = targets.silhouette_dt[view, :h, :w][sil].sum()
    if need_chamfer and sil.any() and obs.any():
        stats[SUM_DT] = chamfer_34(sil)[obs].sum()
    stats[BOUNDARY] = boundary.sum()
    stats[BOUNDARY_OFF] = targets.edge_off[view, :h, :w][boundary].sum()
    stats[SUM_EDGE_DT] = targets.edge_dt[view, :h, :w][boundary].sum()
    hist = np.zeros((n_parts, 2, N_BINS), dtype=np.int64)
    if n_parts:
        part = labels[sil].astype(np.int64) - 1
        for ch in range(2):
            bins = targets.ab_bins[view, :h, :w, ch][sil].astype(np.int64)
            np.add.at(hist[:, ch], (part, bins), 1)
    return stats, hist


def statistics(uv, z, faces, face_label, targets: FrameTargets, need_chamfer=True, n_parts=0, cull=0):
    """Reference path: (P,C,N_STATS) statistics and (P,C,S,2,K) histograms (S = n_parts, 0 = no colour)."""
    P, C = uv.shape[:2]
    stats = np.zeros((P, C, N_STATS))
    hist = np.zeros((P, C, n_parts, 2, N_BINS), dtype=np.int64)
    for p in range(P):
        for c in range(C):
            labels = rasterize(uv[p, c], z[p, c], faces, face_label, int(targets.widths[c]),
                               int(targets.heights[c]), cull)
            stats[p, c], hist[p, c] = view_statistics(labels, targets, c, need_chamfer, n_parts)
    return stats, hist
