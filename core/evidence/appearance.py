"""Whose landmarks these are, told by clothes: the colours of the person the landmark model found in a view
against the colours the tracked actor wore in the take's first frames.

The single-person landmark model returns whoever is most visible in its crop; where another person passes in front
of (or behind) the actor, a view's landmarks can be that person's, and when several views agree on them nothing
geometric tells (docs/how-it-tracks.md, "Other people in the room"). The clothes do: a signature of the shirt (the
torso between the shoulder and hip landmarks) and the trousers (strips along the thighs), as histograms of colour
relative to the whole picture's (so a light that dims or turns warmer changes the picture and the person alike),
compared with the actor's signatures of the first frames by the Bhattacharyya coefficient.
"""
from __future__ import annotations

import cv2
import numpy as np

# BlazePose's landmarks: shoulders, hips, knees (left, right)
SHOULDERS, HIPS, KNEES = (11, 12), (23, 24), (25, 26)
# the torso quadrilateral drawn this share of the way towards its centre, so that its pixels are the shirt's even
# where the landmarks sit a few pixels off the body's outline [DESIGN]
TORSO_SHRINK = 0.25
# a thigh strip's width as a share of the thigh's length (a thigh is about a third as wide as long) [DESIGN]
THIGH_WIDTH = 0.22
# colours are taken relative to the picture's: each channel over the picture's median, the median made mid-grey
# (a light that dims or turns warmer scales the channels of the picture and the person alike)
GREY = 128.0
L_BINS, AB_BINS = 4, 12
AB_HALF_RANGE = 36.0   # 8-bit Lab units either side of grey
# a landmark outlines a region when the model's visibility reaches this [DESIGN]
OUTLINE_VISIBILITY = 0.5
# below this many pixels a region says nothing (a torso seen edge-on, a thigh hidden)
MIN_PIXELS = 40
# every STRIDE-th pixel of the picture (each way) gives its median colour, and a region gives at most MAX_PIXELS
STRIDE = 8
MAX_PIXELS = 4000


def _local_mask(shape, points, pad):
    """An empty mask over the part of a (height, width) picture around `points` (N,2) widened by `pad` pixels, and
    its top-left corner; None where that part is outside the picture."""
    h, w = shape[:2]
    x0, y0 = np.maximum(np.floor(points.min(axis=0) - pad), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(points.max(axis=0) + pad) + 1, (w, h)).astype(int)
    if x1 <= x0 or y1 <= y0:
        return None, None
    return np.zeros((y1 - y0, x1 - x0), np.uint8), np.array([x0, y0])


def _torso(shape, uv, visible):
    """The torso's mask and its corner (see _local_mask), or None where the landmarks do not outline it."""
    corners = [SHOULDERS[0], SHOULDERS[1], HIPS[1], HIPS[0]]
    if not all(visible[i] for i in corners):
        return None
    quad = uv[corners]
    quad = quad + TORSO_SHRINK * (quad.mean(axis=0) - quad)
    mask, corner = _local_mask(shape, quad, 1)
    if mask is None:
        return None
    cv2.fillConvexPoly(mask, np.round(quad - corner).astype(np.int32), 1)
    return mask, corner


def _thighs(shape, uv, visible):
    """The thighs' mask (the middle of each visible thigh) and its corner, or None where no thigh is outlined."""
    strips = []
    for hip, knee in zip(HIPS, KNEES):
        a, b = uv[hip], uv[knee]
        length = float(np.linalg.norm(b - a)) if visible[hip] and visible[knee] else 0.0
        if length >= 4:  # away from the hip joint's edge and the knee
            strips.append((a + 0.2 * (b - a), a + 0.8 * (b - a), max(1, int(round(THIGH_WIDTH * length)))))
    if not strips:
        return None
    ends = np.array([p for a, b, _ in strips for p in (a, b)])
    mask, corner = _local_mask(shape, ends, max(t for *_, t in strips))
    if mask is None:
        return None
    for a, b, thickness in strips:
        cv2.line(mask, tuple(int(v) for v in np.round(a - corner)), tuple(int(v) for v in np.round(b - corner)), 1,
                 thickness)
    return mask, corner


def picture_reference(image_bgr):
    """The picture's median colour (B, G, R), what a region's colours are taken relative to."""
    sample = np.asarray(image_bgr[::STRIDE, ::STRIDE], dtype=np.float64).reshape(-1, 3)
    return np.maximum(np.median(sample, axis=0), 1.0)


def _histogram(bgr_pixels, reference):
    """Normalised (L_BINS, AB_BINS, AB_BINS) Lab histogram of BGR pixels (N,3) relative to the picture's colour."""
    balanced = np.clip(bgr_pixels * (GREY / reference), 0, 255).astype(np.uint8)
    lab = cv2.cvtColor(balanced[None], cv2.COLOR_BGR2LAB)[0].astype(np.float64)
    li = np.clip((lab[:, 0] / 256.0 * L_BINS).astype(int), 0, L_BINS - 1)
    ab = (lab[:, 1:] - 128.0 + AB_HALF_RANGE) / (2 * AB_HALF_RANGE) * AB_BINS
    ai = np.clip(ab.astype(int), 0, AB_BINS - 1)
    flat = (li * AB_BINS + ai[:, 0]) * AB_BINS + ai[:, 1]
    hist = np.bincount(flat, minlength=L_BINS * AB_BINS * AB_BINS).reshape(L_BINS, AB_BINS, AB_BINS).astype(float)
    # spread each count over its neighbours: noise and a slight change of light move colours across bin edges
    hist = np.stack([cv2.GaussianBlur(h, (0, 0), 0.8) for h in hist])
    return hist / max(hist.sum(), 1e-12)


def clothes_signature(image_bgr, uv, visible):
    """The clothes of the person whose landmarks are `uv` (33,2 pixels; `visible` (33,) bool) in `image_bgr`:
    {"torso": histogram, "thighs": histogram}, a region left out where the landmarks do not outline it or it has
    fewer than MIN_PIXELS pixels; None where neither is there."""
    uv = np.asarray(uv, dtype=np.float64)
    visible = np.asarray(visible, dtype=bool) & np.all(np.isfinite(uv), axis=1)
    reference = picture_reference(image_bgr)
    out = {}
    for name, region in (("torso", _torso(image_bgr.shape, uv, visible)),
                         ("thighs", _thighs(image_bgr.shape, uv, visible))):
        if region is None:
            continue
        mask, (x0, y0) = region
        ys, xs = np.nonzero(mask)
        if len(ys) < MIN_PIXELS:
            continue
        ys, xs = ys + y0, xs + x0
        step = max(1, len(ys) // MAX_PIXELS)  # a histogram of a few thousand pixels says as much as of all
        out[name] = _histogram(image_bgr[ys[::step], xs[::step]].astype(np.float64), reference)
    return out or None


def likeness(signature, exemplars):
    """How much `signature` looks like the actor, 0 (nothing alike) to 1 (the same): per region, the Bhattacharyya
    coefficient with the most alike of `exemplars` (the actor's signatures); then the least alike region, so that a
    shirt of another colour is not made up for by trousers like the actor's. None where they share no region."""
    if not signature or not exemplars:
        return None
    best = {}
    for ex in exemplars:
        for region in signature.keys() & ex.keys():
            bc = float(np.sum(np.sqrt(signature[region] * ex[region])))
            best[region] = max(bc, best.get(region, 0.0))
    return min(best.values()) if best else None
