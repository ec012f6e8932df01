"""All per-frame image features of one camera view, at the feature resolution of the renderer.

Silhouette + its distance map (silhouette term, eq. 7), Sobel edges + truncated distance map (edge
term, eq. 9) and diffused CIELab a,b (colour term, eqs. 10-11).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .background import BackgroundModel, as_bgr_float
from .diffusion import edge_enhancing_diffusion
from .errors import FeatureInputError
from .mask_cleanup import check_mask

EDGE_DT_CAP_PX = 20.0      # edge distance truncation at full resolution (algorithms.md A12)


@dataclass
class ViewFeatures:
    """One camera, one frame. All maps are HxW at the feature resolution (`scale` x the camera image)."""
    silhouette: np.ndarray      # bool HxW, True on the subject
    silhouette_dt: np.ndarray   # float32 HxW, distance to the nearest silhouette pixel (0 inside), untruncated
    edges: np.ndarray           # bool HxW, True on Sobel edges
    edge_dt: np.ndarray         # float32 HxW, distance to the nearest edge pixel, capped at 20 px * scale
    lab_ab: np.ndarray          # float32 HxWx2, CIELab a,b (native units), edge-enhancing diffused
    scale: float = 1.0


def distance_to_mask(mask: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance of every pixel to the nearest True pixel (0 on them), float32.

    With no True pixel at all every distance is the image diagonal (farther than any real distance)."""
    m = check_mask(mask)
    if not m.any():
        return np.full(m.shape, float(np.hypot(*m.shape)), dtype=np.float32)
    return cv2.distanceTransform((~m).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def sobel_magnitude(grey: np.ndarray) -> np.ndarray:
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REFLECT)
    return cv2.magnitude(gx, gy)


def subject_region(silhouette: np.ndarray, margin_fraction: float = 0.1) -> tuple[slice, slice]:
    """Bounding box of the silhouette grown by a margin (10% of its larger side, at least 4 px)."""
    ys, xs = np.nonzero(silhouette)
    if ys.size == 0:
        return slice(None), slice(None)
    margin = max(4, int(round(margin_fraction * max(np.ptp(ys) + 1, np.ptp(xs) + 1))))
    h, w = silhouette.shape
    return (slice(max(0, ys.min() - margin), min(h, ys.max() + margin + 1)),
            slice(max(0, xs.min() - margin), min(w, xs.max() + margin + 1)))


def sobel_edges(image_bgr: np.ndarray, silhouette: np.ndarray | None = None, percentile: float = 90) -> np.ndarray:
    """Edge pixels: Sobel magnitude of the grey image above its `percentile` inside the grown
    bounding box of the silhouette (whole image if there is none). Bool HxW."""
    if not 0 <= percentile < 100:
        raise FeatureInputError(f"edge_percentile must be in [0, 100), got {percentile}")
    grey = cv2.cvtColor(as_bgr_float(image_bgr), cv2.COLOR_BGR2GRAY)
    mag = sobel_magnitude(grey)
    region = subject_region(silhouette) if silhouette is not None else (slice(None), slice(None))
    threshold = float(np.percentile(mag[region], percentile))
    # Strictly above, and above a floor: a flat image has no edges, not every pixel an edge.
    return mag > max(threshold, 1e-3)


def lab_ab(image_bgr: np.ndarray) -> np.ndarray:
    """CIELab a,b channels (about -128..127) of a BGR image, float32 HxWx2."""
    lab = cv2.cvtColor(as_bgr_float(image_bgr) / np.float32(255.0), cv2.COLOR_BGR2Lab)
    return np.ascontiguousarray(lab[:, :, 1:3])


def resize_mask(mask: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
    """Area-resample a bool mask: a feature pixel is set when at least half of it was covered."""
    if mask.shape[::-1] == tuple(size_wh):
        return mask
    return cv2.resize(mask.astype(np.float32), size_wh, interpolation=cv2.INTER_AREA) >= 0.5


def feature_size(shape, scale: float) -> tuple[int, int]:
    """(width, height) of the feature maps for an image of `shape` at `scale`."""
    if not 0 < scale <= 1.0:
        raise FeatureInputError(f"scale must be in (0, 1] (features are computed at or below the camera "
                                f"resolution), got {scale}")
    return max(1, int(round(shape[1] * scale))), max(1, int(round(shape[0] * scale)))


def compute_view_features(image_bgr: np.ndarray, background: BackgroundModel | None, scale: float = 1.0,
                          diffuse: bool = True, edge_percentile: float = 90,
                          silhouette: np.ndarray | None = None) -> ViewFeatures:
    """Features of one frame of one camera at `scale` x its resolution (scale 0.5 -> half width/height).

    The silhouette is found at the camera resolution (the background model's, unless a `silhouette` is
    given at the camera or the feature resolution, e.g. the learned person mask) and area-resampled.
    """
    image = np.asarray(image_bgr)
    # Integer footage is resampled before it becomes float: an HD frame's float copy costs more than the rest.
    if image.dtype not in (np.uint8, np.uint16) or image.ndim != 3 or image.shape[2] != 3:
        image = as_bgr_float(image, "frame") / np.float32(255.0)  # checks shape and range; float in [0, 1]
    size = feature_size(image.shape, scale)
    if silhouette is None:
        if background is None:
            raise FeatureInputError("compute_view_features needs a background model or a silhouette")
        silhouette = background.silhouette(image_bgr)
    silhouette = resize_mask(check_mask(silhouette), size)
    small = image if size == image.shape[1::-1] else cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    small01 = np.clip(as_bgr_float(small, "frame") / np.float32(255.0), 0.0, 1.0)
    edges = sobel_edges(small01, silhouette, edge_percentile)
    cap = EDGE_DT_CAP_PX * scale
    edge_dt = np.minimum(distance_to_mask(edges), np.float32(cap)).astype(np.float32)
    ab = lab_ab(small01)
    if diffuse:
        ab = edge_enhancing_diffusion(ab)
    return ViewFeatures(silhouette=silhouette, silhouette_dt=distance_to_mask(silhouette), edges=edges,
                        edge_dt=edge_dt, lab_ab=ab.astype(np.float32), scale=float(scale))
