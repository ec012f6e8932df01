"""Bring a background image to the exposure of a frame, so light changes are not taken for the subject.

Two models, both fitted on the pixels that are background in the frame (most of them):

* gain: one ratio per channel. Right for a linear camera whose exposure or white balance changes.
* curve: one monotone curve per channel (binned medians of frame vs background, made non-decreasing by
  isotonic regression). Right when the camera's tone curve is not linear (filmic/AgX renders, video
  gamma with a knee): a dimmer light then darkens shadows and highlights by different ratios, which a
  single gain leaves as false foreground over whole walls. Beyond the range the fit covers it continues
  with the end ratios, as a gain would.
"""
from __future__ import annotations

import numpy as np

EXPOSURE_MODELS = ("curve", "gain", "none")
_CURVE_BINS = 32
_MIN_BIN_FRACTION = 0.002   # a bin must hold this share of the used pixels (and 50) to be trusted
# A curve of 32 binned medians needs far fewer samples than an HD frame has (2 M per channel, whose sorting
# made the clip-median background of four 1080x1920 videos take over a minute): above this many, an even
# stride over the samples is used. 640x480 footage (307 k pixels) is fitted on all of its pixels.
_MAX_CURVE_SAMPLES = 400_000


def usable_pixels(image: np.ndarray, background: np.ndarray, use: np.ndarray | None,
                  keep_clipped: bool = False) -> np.ndarray:
    """Per channel: pixels exposed well enough in both images to say something about the exposure.

    A ratio is meaningless where the frame clipped; a curve is not: it should clip there too, and
    dropping only the clipped samples of a bin would bias its median low."""
    valid = (background > 12.0) & (background < 245.0)
    if not keep_clipped:
        valid &= image < 250.0
    if use is not None:
        valid &= use[:, :, None]
    return valid


def channel_gain(image: np.ndarray, background: np.ndarray, use: np.ndarray | None = None) -> np.ndarray:
    """Robust per-channel ratio image/background (median over the usable pixels)."""
    valid = usable_pixels(image, background, use)
    gains = np.ones(3, dtype=np.float32)
    for c in range(3):
        sel = valid[:, :, c]
        if np.count_nonzero(sel) > 100:
            gains[c] = np.median(image[:, :, c][sel] / background[:, :, c][sel])
    return gains


def isotonic(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-decreasing fit (pool adjacent violators)."""
    means, sums, sizes = [], [], []
    for v, w in zip(values.astype(float), weights.astype(float)):
        means.append(v)
        sums.append(w)
        sizes.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            w2 = sums[-2] + sums[-1]
            means[-2:] = [(means[-2] * sums[-2] + means[-1] * sums[-1]) / w2]
            sums[-2:] = [w2]
            sizes[-2:] = [sizes[-2] + sizes[-1]]
    return np.repeat(means, sizes)


def fit_tone_curve(source: np.ndarray, target: np.ndarray):
    """Knots (x, y) of a non-decreasing map source -> target from paired samples of one channel, or
    None when fewer than two intensity bins hold enough samples."""
    step = -(-source.size // _MAX_CURVE_SAMPLES)
    if step > 1:
        source, target = source[::step], target[::step]
    bins = np.clip((source * (_CURVE_BINS / 256.0)).astype(int), 0, _CURVE_BINS - 1)
    counts = np.bincount(bins, minlength=_CURVE_BINS)
    trusted = np.flatnonzero(counts >= max(50, _MIN_BIN_FRACTION * source.size))
    if trusted.size < 2:
        return None
    order = np.argsort(bins, kind="stable")
    sorted_target = target[order]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    medians = np.array([np.median(sorted_target[starts[k]:starts[k] + counts[k]]) for k in trusted])
    # x at each bin's median source value, so the knots sit where the data are
    sorted_source = source[order]
    knots_x = np.array([np.median(sorted_source[starts[k]:starts[k] + counts[k]]) for k in trusted])
    return knots_x, isotonic(medians, counts[trusted])


def apply_tone_curve(values: np.ndarray, knots) -> np.ndarray:
    x, y = knots
    mapped = np.interp(values, x, y)
    low_ratio = y[0] / max(x[0], 1e-3)
    high_ratio = y[-1] / max(x[-1], 1e-3)
    mapped = np.where(values < x[0], values * low_ratio, mapped)
    return np.where(values > x[-1], values * high_ratio, mapped)


def match_exposure(background: np.ndarray, image: np.ndarray, model: str = "curve",
                   use: np.ndarray | None = None) -> np.ndarray:
    """`background` (float HxWx3, 0..255) as it would look at `image`'s exposure, clipped like a sensor.

    `use` (bool HxW) restricts the fit to pixels known to be background in `image`."""
    if model == "none":
        return background
    if model == "gain":
        return np.minimum(background * channel_gain(image, background, use), np.float32(255.0))
    if model != "curve":
        raise ValueError(f"unknown exposure model {model!r}; use one of {EXPOSURE_MODELS}")
    valid = usable_pixels(image, background, use, keep_clipped=True)
    out = np.empty_like(background)
    for c in range(3):
        sel = valid[:, :, c]
        knots = fit_tone_curve(background[:, :, c][sel], image[:, :, c][sel])
        if knots is None:   # too little to fit a curve: a gain (or nothing) is all the data support
            out[:, :, c] = background[:, :, c] * channel_gain(image, background, use)[c]
        else:
            out[:, :, c] = apply_tone_curve(background[:, :, c], knots)
    return np.clip(out, 0.0, 255.0).astype(np.float32)
