"""Turning a raw per-pixel foreground decision into a plausible body silhouette.

Opening removes speckle, closing bridges thin gaps, small blobs are dropped, only components comparable
to the largest one are kept (the subject), and small enclosed holes are filled (clothing that happens
to match the background). Large enclosed holes are kept: the gap between an arm on the hip and the
torso is real background. Radii are given for a 480-pixel short side and scale with the resolution.
"""
import cv2
import numpy as np

from .errors import FeatureInputError

REFERENCE_SHORT_SIDE = 480.0


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def scaled_radius(radius: float, shape) -> int:
    """A radius given for a 480-pixel short side, at the resolution of `shape`."""
    return int(round(radius * min(shape[:2]) / REFERENCE_SHORT_SIDE))


def check_mask(mask, name="mask") -> np.ndarray:
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise FeatureInputError(f"{name} must be a 2-D HxW array, got shape {arr.shape}")
    return arr.astype(bool)


def clean_silhouette(mask: np.ndarray, open_radius: float = 1.0, close_radius: float = 3.0,
                     min_blob_fraction: float = 2e-4, keep_fraction: float = 0.03,
                     max_hole_fraction: float = 0.02) -> np.ndarray:
    """Clean a raw foreground mask (bool HxW) -> bool HxW.

    min_blob_fraction: blobs smaller than this share of the image are noise.
    keep_fraction: components smaller than this share of the largest component are dropped.
    max_hole_fraction: enclosed holes smaller than this share of the kept area are filled.
    """
    fg = check_mask(mask).astype(np.uint8)
    r_open, r_close = scaled_radius(open_radius, fg.shape), scaled_radius(close_radius, fg.shape)
    if r_open > 0:
        fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, _disc(r_open))
    if r_close > 0:
        # Pad so that closing does not glue the silhouette to the image border.
        pad = r_close + 1
        fg = cv2.morphologyEx(cv2.copyMakeBorder(fg, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0),
                              cv2.MORPH_CLOSE, _disc(r_close))[pad:-pad, pad:-pad]
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        return np.zeros(fg.shape, dtype=bool)
    areas = stats[1:, cv2.CC_STAT_AREA]
    min_area = max(min_blob_fraction * fg.size, keep_fraction * areas.max())
    keep_labels = np.flatnonzero(areas >= min_area) + 1
    out = np.isin(labels, keep_labels)
    return fill_small_holes(out, max_hole_fraction * out.sum())


def fill_small_holes(mask: np.ndarray, max_area: float) -> np.ndarray:
    """Fill background regions that touch no image border and are smaller than max_area pixels."""
    bg = (~mask).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(bg, connectivity=4)
    if n <= 1:
        return mask.copy()
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    holes = np.ones(n, dtype=bool)
    holes[0] = False               # label 0 is the foreground itself
    holes[border] = False
    holes &= stats[:, cv2.CC_STAT_AREA] < max_area
    return mask | holes[labels]


def silhouette_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks of the same shape (1.0 when both are empty)."""
    a, b = check_mask(a, "first mask"), check_mask(b, "second mask")
    if a.shape != b.shape:
        raise FeatureInputError(f"masks differ in size: {a.shape} vs {b.shape}; compare masks of the same view "
                                f"at the same resolution")
    union = np.count_nonzero(a | b)
    if union == 0:
        return 1.0
    return float(np.count_nonzero(a & b) / union)
