"""Background subtraction per camera: which pixels show the subject.

The colour test is shadow-robust (Horprasert-style): each pixel colour I is compared with the
background colour B along B (brightness ratio alpha = I.B/|B|^2) and across it (chroma distortion
|I - alpha B|). A shadow darkens a pixel but keeps its chromaticity, so a pixel is foreground only if

* its chroma distortion exceeds the noise threshold, or
* it is much darker than any plausible shadow (alpha < shadow_min), or much brighter than the
  background (alpha > bright_max), by more than the noise threshold in absolute terms,

and it is not explained by the texture test: where the background is textured, a shadow (even a deep
one) or a local light change only scales the texture, so the local grey-level correlation between frame
and background stays high, while the subject replaces the texture. Pixels that are not too dark and
only mildly off in hue are returned to the background when that correlation is high.

Global illumination changes (exposure, dimming lights, white balance drift) are taken out first: the
background is brought to the frame's exposure with a per-channel tone curve or gain (exposure.py).
The noise level is estimated from each frame (most pixels are background), so no per-camera tuning is needed.
"""
from __future__ import annotations

import cv2
import numpy as np

from .errors import FeatureInputError
from .exposure import EXPOSURE_MODELS, match_exposure
from .mask_cleanup import clean_silhouette

# 30th percentile of the Rayleigh distribution / its scale: turns that percentile of the chroma
# distortion (robust to up to 70 % foreground) into the noise sigma.
_RAYLEIGH_PCT30 = float(np.sqrt(-2.0 * np.log(0.7)))
# Median of the chi distribution with 3 degrees of freedom (norm of a 3-D standard normal vector).
_CHI3_MEDIAN = 1.5382

COLOUR_DEFAULTS = dict(
    blur_sigma=0.0,      # pre-blur (pixels at a 480-pixel short side) against sensor noise
    chroma_k=6.0,        # chroma threshold in noise sigmas (video coding makes the tails heavy)
    chroma_min=6.0,      # chroma threshold floor, 0-255 units
    shadow_min=0.7,      # darkest brightness ratio still accepted as shadow on the background
    bright_max=1.1,      # brightest ratio still accepted as background (highlights, light changes)
    bright_k=4.0,        # absolute brightness-difference threshold in noise sigmas
    bright_min=10.0,     # and its floor, 0-255 units
    exposure="curve",    # how the background follows the frame's light: "curve", "gain" or "none"
    shadow_chroma_factor=1.0,  # chroma threshold factor for darkened pixels (shadows shift hue a little)
    texture_ncc_min=0.5,  # a darkened/tinted pixel whose local texture correlates this well with the
                          # background's is a shadow or light change on it, not the subject (0 = off)
    texture_min=3.0,      # ... only where the background has texture (grey std in the window, 0-255)
    texture_window=11,    # window side at a 480-pixel short side
    texture_alpha_min=0.25,   # ... and only for pixels no darker than this ratio
    texture_chroma_max=1.5,   # ... whose chroma distortion is below this many chroma thresholds
    saturated_relax=1.0,  # >1 raises the chroma threshold where the background is clipped (hue unreliable there)
)
CLEANUP_DEFAULTS = dict(open_radius=1.0, close_radius=3.0, min_blob_fraction=2e-4, keep_fraction=0.03,
                        max_hole_fraction=0.02)


def as_bgr_float(image, name="image") -> np.ndarray:
    """uint8 / uint16 / float-in-[0,1] BGR image -> float32 HxWx3 in 0..255."""
    arr = np.asarray(image)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise FeatureInputError(f"{name} must be a colour HxWx3 BGR image, got shape {arr.shape}; "
                                f"load it with cv2.imread(path, cv2.IMREAD_COLOR)")
    if arr.dtype == np.uint8:
        return arr.astype(np.float32)
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) * np.float32(255.0 / 65535.0)
    if np.issubdtype(arr.dtype, np.floating):
        if arr.size and (np.nanmin(arr) < -1e-3 or np.nanmax(arr) > 1.0 + 1e-3):
            raise FeatureInputError(f"{name} is a float image outside [0, 1] (range {np.nanmin(arr):.3g}.."
                                    f"{np.nanmax(arr):.3g}); pass uint8 or divide by 255")
        return arr.astype(np.float32) * np.float32(255.0)
    raise FeatureInputError(f"{name} has unsupported dtype {arr.dtype}; use uint8, uint16 or float in [0, 1]")


def _split_options(opts: dict) -> tuple[dict, dict]:
    unknown = set(opts) - set(COLOUR_DEFAULTS) - set(CLEANUP_DEFAULTS)
    if unknown:
        raise FeatureInputError(f"unknown background option(s) {sorted(unknown)}; valid options are "
                                f"{sorted(COLOUR_DEFAULTS) + sorted(CLEANUP_DEFAULTS)}")
    colour = {**COLOUR_DEFAULTS, **{k: v for k, v in opts.items() if k in COLOUR_DEFAULTS}}
    cleanup = {**CLEANUP_DEFAULTS, **{k: v for k, v in opts.items() if k in CLEANUP_DEFAULTS}}
    if colour["exposure"] not in EXPOSURE_MODELS:
        raise FeatureInputError(f"exposure must be one of {EXPOSURE_MODELS}, got {colour['exposure']!r}")
    if not 0.0 < colour["shadow_min"] < 1.0 < colour["bright_max"]:
        raise FeatureInputError("need 0 < shadow_min < 1 < bright_max (brightness ratios of the background)")
    return colour, cleanup


def _temporal_median(frames, transform=None, rows_per_strip=64) -> np.ndarray:
    """Per-pixel median over `frames` (each HxW[xC]) as float32, of transform(strip, rows) when given, a
    strip of rows at a time: the same numbers as np.median over the stacked clip, without the stack (25
    HD frames are 0.6 GB of float32, and sweeping it costs more than the medians)."""
    H = frames[0].shape[0]
    out = None
    for r0 in range(0, H, rows_per_strip):
        rows = slice(r0, min(H, r0 + rows_per_strip))
        strip = np.stack([f[rows] for f in frames])
        if transform is not None:
            strip = transform(strip, rows)
        m = np.median(strip, axis=0)
        if out is None:
            out = np.empty((H,) + m.shape[1:], dtype=np.float32)
        out[rows] = m
    return out


def _blur(image: np.ndarray, sigma_at_480: float) -> np.ndarray:
    sigma = sigma_at_480 * min(image.shape[:2]) / 480.0
    if sigma <= 0.05:
        return image
    return cv2.GaussianBlur(image, (0, 0), sigma)


def colour_foreground(image: np.ndarray, bg: np.ndarray, noise_map: np.ndarray | None = None,
                      noise_scale: float = 1.0, **colour) -> np.ndarray:
    """Raw foreground decision (bool HxW) for blurred float images in 0..255 of the same size.

    `bg` must already be at the frame's exposure (match_exposure); `noise_scale` carries the per-pixel
    noise levels, measured at the background's exposure, over to the frame's.
    """
    o = {**COLOUR_DEFAULTS, **colour}
    bb = np.einsum("ijc,ijc->ij", bg, bg) + 1.0
    alpha = np.einsum("ijc,ijc->ij", image, bg) / bb
    chroma = np.linalg.norm(image - alpha[:, :, None] * bg, axis=2)
    sigma = max(float(np.percentile(chroma, 30)) / _RAYLEIGH_PCT30, 0.25)
    t_chroma = max(o["chroma_min"], o["chroma_k"] * sigma)
    t_bright = max(o["bright_min"], o["bright_k"] * sigma)
    if noise_map is not None:
        scaled_noise = noise_map * np.float32(noise_scale)
        t_chroma = np.maximum(t_chroma, o["chroma_k"] * scaled_noise)
        t_bright = np.maximum(t_bright, o["bright_k"] * scaled_noise)
    if o["saturated_relax"] != 1.0:
        clipped = np.any(bg >= 250.0, axis=2)
        t_chroma = np.where(clipped, o["saturated_relax"] * t_chroma, t_chroma)
    if o["shadow_chroma_factor"] != 1.0:
        t_chroma = np.where(alpha < 0.95, o["shadow_chroma_factor"] * t_chroma, t_chroma)
    bright_diff = (alpha - 1.0) * np.sqrt(bb)
    fg = ((chroma > t_chroma)
          | ((alpha < o["shadow_min"]) & (-bright_diff > t_bright))
          | ((alpha > o["bright_max"]) & (bright_diff > t_bright)))
    if o["texture_ncc_min"] > 0:
        ncc, bg_std = texture_correlation(image, bg, o["texture_window"])
        # Only colour changes a shadow or a light could make: not too dark, hue not far off.
        plausible = (alpha > o["texture_alpha_min"]) & (chroma < o["texture_chroma_max"] * t_chroma)
        fg &= ~((ncc > o["texture_ncc_min"]) & (bg_std > o["texture_min"]) & plausible)
    return fg


def texture_correlation(image: np.ndarray, background: np.ndarray, window_at_480: float):
    """Local normalised cross-correlation of the grey images and the background's local grey std.

    A shadow or a light change scales the background's texture, so the correlation stays high; the
    subject replaces the texture, so it drops."""
    side = max(3, int(round(window_at_480 * min(image.shape[:2]) / 480.0)) | 1)
    grey_i = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    grey_b = cv2.cvtColor(background, cv2.COLOR_BGR2GRAY)

    def mean(x):
        return cv2.boxFilter(x, -1, (side, side), borderType=cv2.BORDER_REFLECT)

    mi, mb = mean(grey_i), mean(grey_b)
    var_i = np.maximum(mean(grey_i * grey_i) - mi * mi, 0.0)
    var_b = np.maximum(mean(grey_b * grey_b) - mb * mb, 0.0)
    cov = mean(grey_i * grey_b) - mi * mb
    ncc = cov / np.sqrt(np.maximum(var_i * var_b, 1e-6))
    return ncc, np.sqrt(var_b)


class BackgroundModel:
    """Per-camera background: an image of the empty scene (given, or estimated from the clip), an
    optional per-pixel noise level, and the options of the colour test and of the clean-up."""

    def __init__(self, background_bgr: np.ndarray, noise_map: np.ndarray | None = None, **opts):
        self.colour_options, self.cleanup_options = _split_options(opts)
        self.background = as_bgr_float(background_bgr, "background plate")
        self.shape = self.background.shape[:2]
        self._blurred = _blur(self.background, self.colour_options["blur_sigma"])
        self.noise_map = noise_map

    @classmethod
    def from_plate(cls, plate_bgr: np.ndarray, **opts) -> "BackgroundModel":
        """From an empty-scene plate of this camera (same resolution as the frames)."""
        return cls(plate_bgr, **opts)

    @classmethod
    def from_frames(cls, frames_bgr, method: str = "median", max_frames: int = 25, **opts) -> "BackgroundModel":
        """Without a plate: from the clip itself. `frames_bgr` should span the clip (the subject must move
        so that each pixel shows the background in most of the chosen frames); at most `max_frames`
        evenly spaced frames are used.

        median: per-pixel temporal median of exposure-matched frames, with a per-pixel noise level
                (median absolute deviation over the frames) that raises thresholds where the clip flickers.
        mog2 / knn: the empty scene as estimated by OpenCV's mixture / nearest-neighbour subtractors
                (getBackgroundImage), then the same colour test. Weaker than the median on short clips.
        """
        frames = list(frames_bgr)
        if len(frames) < 3:
            raise FeatureInputError(f"need at least 3 frames to estimate a background, got {len(frames)}; "
                                    f"pass frames spread over the whole clip or use from_plate()")
        if max_frames < 3:
            raise FeatureInputError(f"max_frames must be at least 3, got {max_frames}")
        pick = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames))).round().astype(int))
        chosen = [as_bgr_float(frames[i], f"frame {i}") for i in pick]
        shape = chosen[0].shape
        for i, f in zip(pick, chosen):
            if f.shape != shape:
                raise FeatureInputError(f"frame {i} is {f.shape[1]}x{f.shape[0]} but frame {pick[0]} is "
                                        f"{shape[1]}x{shape[0]}; all frames of one camera must have one size")
        if method == "median":
            return cls._from_median(chosen, **opts)
        if method in ("mog2", "knn"):
            return cls._from_subtractor(chosen, method, **opts)
        raise FeatureInputError(f"unknown background method {method!r}; use 'median', 'mog2' or 'knn'")

    @classmethod
    def _from_median(cls, frames, **opts) -> "BackgroundModel":
        colour, _ = _split_options(opts)
        blurred = [_blur(f, colour["blur_sigma"]) for f in frames]
        median = _temporal_median(blurred)
        if colour["exposure"] != "none":
            # Bring every frame to a common exposure before the median (the light may change over the clip).
            blurred = [match_exposure(f, median, colour["exposure"]) for f in blurred]
            median = _temporal_median(blurred)
        noise_map = _temporal_median(blurred, lambda strip, rows: np.linalg.norm(strip - median[rows], axis=-1))
        noise_map = (noise_map / _CHI3_MEDIAN).astype(np.float32)
        model = cls(np.clip(median + 0.5, 0, 255).astype(np.uint8), noise_map=noise_map, **opts)
        model._blurred = median          # already blurred: compare with it directly, without re-blurring
        return model

    @classmethod
    def _from_subtractor(cls, frames, method, passes: int = 3, **opts) -> "BackgroundModel":
        n = len(frames)
        if method == "mog2":
            sub = cv2.createBackgroundSubtractorMOG2(history=n, varThreshold=16, detectShadows=True)
        else:
            sub = cv2.createBackgroundSubtractorKNN(history=n, dist2Threshold=400.0, detectShadows=True)
        for _ in range(passes):    # a few passes over the chosen frames let the model settle
            for f in frames:
                sub.apply(np.clip(f, 0, 255).astype(np.uint8))
        # OpenCV's per-pixel decision knows neither shadows of this kind nor exposure changes: use the
        # subtractor only to estimate the empty scene, and decide with the shadow-robust colour test.
        return cls(sub.getBackgroundImage(), **opts)

    def _check_size(self, image: np.ndarray):
        if image.shape[:2] != tuple(self.shape):
            raise FeatureInputError(
                f"frame is {image.shape[1]}x{image.shape[0]} but the background model is "
                f"{self.shape[1]}x{self.shape[0]}; use a plate / frames of the same camera at the same resolution")

    def raw_foreground(self, image_bgr: np.ndarray) -> np.ndarray:
        """Per-pixel foreground decision before clean-up (bool HxW)."""
        img = as_bgr_float(image_bgr, "frame")
        self._check_size(img)
        o = self.colour_options
        blurred = _blur(img, o["blur_sigma"])
        if o["exposure"] == "none":
            return colour_foreground(blurred, self._blurred, self.noise_map, **o)
        # Two passes: the second fits the exposure on the pixels the first pass called background.
        first = self._decide(blurred, match_exposure(self._blurred, blurred, o["exposure"]))
        background_px = cv2.erode((~first).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        return self._decide(blurred, match_exposure(self._blurred, blurred, o["exposure"], use=background_px))

    def _decide(self, blurred, matched_background):
        scale = float(matched_background.mean() / max(float(self._blurred.mean()), 1e-3))
        return colour_foreground(blurred, matched_background, self.noise_map, scale, **self.colour_options)

    def silhouette(self, image_bgr: np.ndarray) -> np.ndarray:
        """The subject's silhouette in this frame (bool HxW, cleaned)."""
        return clean_silhouette(self.raw_foreground(image_bgr), **self.cleanup_options)
