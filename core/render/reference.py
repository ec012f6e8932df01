"""The reference rasteriser and likelihood statistics: plain NumPy, written to be obviously right.

Everything the fast path (fast.py) computes is defined here first; tests compare the two.

Rasterisation rules (shared bit for bit with fast.py, which steps the same integers incrementally):
* pixel (row i, column j) is sampled at its centre, the point (x=j, y=i) of the camera's pixel
  coordinates (OpenCV: (0, 0) is the centre of the top-left pixel);
* a triangle is the projection of its three (distorted) vertices, snapped to 1/SUBPIXEL px, joined by
  straight edges; it is skipped if any vertex lies closer than Z_NEAR to the camera plane or if it has
  zero area;
* a pixel centre is inside when all three (integer, exact) edge functions are positive, or zero on an
  edge the top-left rule gives to the triangle (two triangles sharing an edge never both own a pixel);
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

Several actors: a silhouette pixel may hold OTHERS, where another tracked actor's body is. Given the others'
poses, the binary silhouette of all actors together does not depend on this actor's body there (whoever is in
front, the pixel is a body pixel), so those pixels count for nothing: TEMPLATE, OVERLAP, SUM_DI and the
histograms skip them, SUM_DT and the observed count read only value 1 (docs/how-it-tracks.md, "Several actors").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Z_NEAR = 1e-3  # metres: triangles with a vertex closer to the camera plane are not drawn
SUBPIXEL = 256  # vertices snap to 1/256 px: edge functions are then exact integers (and so is the top-left rule)
MAX_COORD_PX = float(1 << 22)  # triangles reaching beyond +-4M px (a vertex almost in the camera plane) are skipped
N_BINS = 64  # colour histogram bins per channel (eq. 10, K = 64)

TEMPLATE, OVERLAP, SUM_DI, SUM_DT, BOUNDARY, BOUNDARY_OFF, SUM_EDGE_DT = range(7)
N_STATS = 7
OTHERS = 2  # silhouette value of the pixels another tracked actor covers (see above)


class RenderInputError(ValueError):
    """Arrays handed to the rasteriser have the wrong shape or contents."""


@dataclass
class FrameTargets:
    """The observed side of one frame, per view, padded to the largest view (H, W).

    widths/heights give each view's real size; pixels outside it are zero and never read.
    """

    widths: np.ndarray  # (C,) int64
    heights: np.ndarray  # (C,) int64
    silhouette: np.ndarray  # (C,H,W) uint8, 1 on the observed subject, OTHERS where another actor is
    silhouette_dt: np.ndarray  # (C,H,W) float64, distance to the observed silhouette (energy pixels)
    edge_off: np.ndarray  # (C,H,W) uint8, E_v: 0 on image edges, 1 elsewhere
    edge_dt: np.ndarray  # (C,H,W) float64, truncated distance to the nearest image edge (energy pixels)
    ab_bins: np.ndarray  # (C,H,W,2) uint8, histogram bin of the diffused a and b channels
    # SUM_DT counts each observed pixel's distance to the template up to this many energy pixels (rounded
    # to the 3-4 chamfer's 1/3 px), so foreground far from the body adds a constant, not a pull.
    chamfer_cap: float = np.inf

    def __post_init__(self):
        self.widths = np.asarray(self.widths, dtype=np.int64)
        self.heights = np.asarray(self.heights, dtype=np.int64)
        self.silhouette = np.ascontiguousarray(self.silhouette, dtype=np.uint8)
        self.silhouette_dt = np.ascontiguousarray(self.silhouette_dt, dtype=np.float64)
        self.edge_off = np.ascontiguousarray(self.edge_off, dtype=np.uint8)
        self.edge_dt = np.ascontiguousarray(self.edge_dt, dtype=np.float64)
        self.ab_bins = np.ascontiguousarray(self.ab_bins, dtype=np.uint8)
        if not self.chamfer_cap > 0:
            raise RenderInputError(f"FrameTargets.chamfer_cap must be > 0 pixels, got {self.chamfer_cap}")
        C, H, W = self.silhouette.shape
        for name in ("silhouette_dt", "edge_off", "edge_dt"):
            if getattr(self, name).shape != (C, H, W):
                raise RenderInputError(f"FrameTargets.{name} has shape {getattr(self, name).shape}; "
                                       f"expected {(C, H, W)} like the silhouettes")
        if self.ab_bins.shape != (C, H, W, 2):
            raise RenderInputError(f"FrameTargets.ab_bins has shape {self.ab_bins.shape}; expected {(C, H, W, 2)}")
        if len(self.widths) != C or len(self.heights) != C or np.any(self.widths > W) or np.any(self.heights > H):
            raise RenderInputError("FrameTargets: one width and height per view, each within the padded size")
        observed = self.silhouette == 1
        self.observed_count = np.array([int(observed[c].sum()) for c in range(C)], dtype=np.int64)
        self.has_others = bool(np.any(self.silhouette == OTHERS))
        box = np.zeros((C, 4), dtype=np.int64)  # y0, y1, x0, x1 inclusive; y1 < y0 when empty
        box[:, 1] = -1
        for c in range(C):
            ys, xs = np.nonzero(observed[c])
            if ys.size:
                box[c] = ys.min(), ys.max(), xs.min(), xs.max()
        self.observed_box = box

    @property
    def n_views(self):
        return len(self.widths)

    def with_others(self, masks):
        """These targets with the pixels of `masks` ((C,H,W) bool: where the other actors' bodies are) set to
        OTHERS, and no edge cost there either (this actor's outline behind another is hidden)."""
        masks = np.asarray(masks, dtype=bool)
        if masks.shape != self.silhouette.shape:
            raise RenderInputError(f"the other actors' masks have shape {masks.shape}; expected "
                                   f"{self.silhouette.shape} like the silhouettes")
        return FrameTargets(self.widths, self.heights, np.where(masks, OTHERS, self.silhouette),
                            self.silhouette_dt, np.where(masks, 0, self.edge_off), np.where(masks, 0.0, self.edge_dt),
                            self.ab_bins, self.chamfer_cap)

    @property
    def chamfer_cap_units(self) -> int:
        """chamfer_cap in the 3-4 chamfer's integer units (3 per pixel); no cap is 2^30 units."""
        return int(min(round(3.0 * self.chamfer_cap), 1 << 30)) if np.isfinite(self.chamfer_cap) else 1 << 30


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
    with np.errstate(invalid="ignore", divide="ignore"):  # points at the camera centre: masked by z later
        for c, cam in enumerate(cameras):
            uv[:, c], z[:, c] = cam.project_with_depth(vertices)
    return uv, z


def snap(uv):
    """Pixel coordinates -> integers in 1/SUBPIXEL px (round half to even), and which points are usable
    (finite and within MAX_COORD_PX)."""
    uv = np.asarray(uv, dtype=np.float64)
    ok = np.all(np.abs(uv) <= MAX_COORD_PX, axis=-1)  # also False for NaN
    return np.rint(np.where(ok[..., None], uv, 0.0) * SUBPIXEL).astype(np.int64), ok


def _edge(ax, ay, bx, by, px, py):
    """Edge function of a->b at p: positive on the inside of a positively oriented triangle. Exact integers."""
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


def _owns_zero_edge(ax, ay, bx, by):
    """Top-left rule for an edge a->b of a positively oriented triangle (y pointing down)."""
    dx, dy = bx - ax, by - ay
    return (dy < 0) | ((dy == 0) & (dx > 0))


def bounding_box_pixels(tri, x0, x1, y0, y1):
    """Every pixel of every listed triangle's bounding box, without a Python loop:
    (triangle index, pixel x, pixel y) per candidate pixel."""
    nx, ny = x1[tri] - x0[tri] + 1, y1[tri] - y0[tri] + 1
    counts = nx * ny
    t = np.repeat(tri, counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    nxt = np.repeat(nx, counts)
    return t, x0[t] + local % nxt, y0[t] + local // nxt


def rasterize(uv, z, faces, face_label, width, height, cull=0):
    """One mesh in one view -> label image (H,W) int16 (0 background, face_label elsewhere).

    cull: 0 draws every triangle; +1 / -1 draws only triangles of positive / negative signed image
    area (back-face culling for a closed mesh whose front faces have that sign).

    All (triangle, pixel-centre) candidates inside each triangle's bounding box are tested at once;
    the z-buffer keeps, per pixel, the largest 1/z and among equals the lowest triangle index.
    """
    z = np.asarray(z, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    labels = np.zeros((height, width), dtype=np.int16)
    if len(faces) == 0:
        return labels
    q, usable = snap(uv)
    a, b, c = q[faces[:, 0]], q[faces[:, 1]], q[faces[:, 2]]
    za, zb, zc = z[faces[:, 0]], z[faces[:, 1]], z[faces[:, 2]]
    area = _edge(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])  # twice the area, in subpixel units^2
    facing = cull * area >= 0
    flip = area < 0  # make every triangle positively oriented: swap b and c
    b, c = np.where(flip[:, None], c, b), np.where(flip[:, None], b, c)
    zb, zc = np.where(flip, zc, zb), np.where(flip, zb, zc)
    area = np.abs(area)
    xs = np.stack([a[:, 0], b[:, 0], c[:, 0]], axis=1)
    ys = np.stack([a[:, 1], b[:, 1], c[:, 1]], axis=1)
    x0 = np.maximum(-((-xs.min(axis=1)) // SUBPIXEL), 0)  # first pixel centre at or right of the box
    x1 = np.minimum(xs.max(axis=1) // SUBPIXEL, width - 1)
    y0 = np.maximum(-((-ys.min(axis=1)) // SUBPIXEL), 0)
    y1 = np.minimum(ys.max(axis=1) // SUBPIXEL, height - 1)
    drawable = usable[faces].all(axis=1) & (np.minimum(np.minimum(za, zb), zc) > Z_NEAR)
    ok = facing & drawable & (area > 0) & (x1 >= x0) & (y1 >= y0)
    tri = np.nonzero(ok)[0]
    if tri.size == 0:
        return labels
    t, px, py = bounding_box_pixels(tri, x0, x1, y0, y1)
    sx, sy = px * SUBPIXEL, py * SUBPIXEL
    ax_, ay_, bx_, by_, cx_, cy_ = a[t, 0], a[t, 1], b[t, 0], b[t, 1], c[t, 0], c[t, 1]
    w0 = _edge(bx_, by_, cx_, cy_, sx, sy)  # weight of a
    w1 = _edge(cx_, cy_, ax_, ay_, sx, sy)  # weight of b
    w2 = _edge(ax_, ay_, bx_, by_, sx, sy)  # weight of c
    inside = ((w0 >= np.where(_owns_zero_edge(bx_, by_, cx_, cy_), 0, 1))
              & (w1 >= np.where(_owns_zero_edge(cx_, cy_, ax_, ay_), 0, 1))
              & (w2 >= np.where(_owns_zero_edge(ax_, ay_, bx_, by_), 0, 1)))
    t, px, py = t[inside], px[inside], py[inside]
    w0, w1, w2 = w0[inside].astype(np.float64), w1[inside].astype(np.float64), w2[inside].astype(np.float64)
    # Interpolated 1/z, the same float operations in the same order as fast.py.
    inv_z = (w0 * (1.0 / za[t]) + w1 * (1.0 / zb[t]) + w2 * (1.0 / zc[t])) * (1.0 / area[t].astype(np.float64))
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
    drawn = labels > 0
    observed = targets.silhouette[view, :h, :w]
    obs = observed == 1
    sil = drawn & (observed != OTHERS)  # the template where no other actor is
    boundary = boundary_mask(labels)
    stats = np.zeros(N_STATS)
    stats[TEMPLATE] = sil.sum()
    stats[OVERLAP] = (sil & obs).sum()
    stats[SUM_DI] = targets.silhouette_dt[view, :h, :w][sil].sum()
    if need_chamfer and drawn.any() and obs.any():
        stats[SUM_DT] = np.minimum(chamfer_34(drawn)[obs], targets.chamfer_cap_units / 3.0).sum()
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
