"""Learned image evidence: a person mask and 33 body landmarks per view, from BlazePose in OpenCV's DNN.

The model (core/data/models/pose_landmark_full.tflite, Apache-2.0) looks at one square 256 x 256 crop.
A model-based tracker knows where the person is, so the crop comes from the projection of the
predicted pose (first frame: the rough placement) grown by a margin; no person detector is needed.
When a view's crop loses the person (low presence), the crop is widened, then placed on the largest
person-like blob of the view's own foreground, before the view is given up for that frame: evidence
from the wrong place is worse than none.

Everything returned is in image pixels of the camera's full-resolution frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .errors import FeatureInputError
from .view_features import resize_mask

MODELS_FOLDER = Path(__file__).resolve().parents[1] / "data" / "models"
# BlazePose GHUM 3D comes in sizes: "full", and "heavy" (the tracker's default), about four times full's weights and
# three times its time per crop (docs/defaults.md, "landmarks").
LANDMARK_MODEL_FILES = {"full": "pose_landmark_full.tflite", "heavy": "pose_landmark_heavy.tflite"}
MODEL_PATH = MODELS_FOLDER / LANDMARK_MODEL_FILES["full"]
INPUT_SIZE = 256
N_LANDMARKS = 33
CROP_MARGIN = 1.35       # the crop's side over the larger side of the projected joints' box [measured, doc]
MIN_PRESENCE = 0.5       # below this the crop is taken to have lost the person
MASK_THRESHOLD = 0.5     # segmentation probability that counts as person
# Second guesses from the model's heatmaps (Identity_3: 39 maps of 64 x 64 logits over the crop). Where
# a landmark is ambiguous (a wrist hidden behind the body, arms crossed) the regressed point is one guess
# and the heatmap often keeps the other as a second peak, a fraction of a logit to about one below the top
# (docs/defaults.md, "ALTERNATIVE_MAX_GAP"). Peaks this far below the landmark's top logit, and
# this far (in crop pixels) from the regressed point, are kept as alternatives; the tracker, not the
# detector, then decides which one the multi-view pose explains (core/evidence/keypoints.py).
HEATMAP_SIZE = 64
ALTERNATIVES = 2         # second guesses kept per landmark
ALTERNATIVE_MAX_GAP = 3.0  # logits below the landmark's top peak
ALTERNATIVE_MIN_DISTANCE = 24.0  # crop pixels (of 256) from the regressed point

# BlazePose's left/right pairs (odd = the person's left): swapping them mirrors a skeleton.
LEFT_RIGHT_PAIRS = ((1, 4), (2, 5), (3, 6), (7, 8), (9, 10), (11, 12), (13, 14), (15, 16), (17, 18),
                    (19, 20), (21, 22), (23, 24), (25, 26), (27, 28), (29, 30), (31, 32))
SWAP_ORDER = np.arange(N_LANDMARKS)
for _a, _b in LEFT_RIGHT_PAIRS:
    SWAP_ORDER[_a], SWAP_ORDER[_b] = _b, _a


class LearnedModelError(FeatureInputError):
    """The landmark model file is missing or cannot be loaded."""


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60, 60)))


# ---------------------------------------------------------------------------------------- crop geometry
@dataclass(frozen=True)
class CropBox:
    """A square window of the image: centre (cx, cy) and side `size` in image pixels, mapped onto the
    model's INPUT_SIZE x INPUT_SIZE input. It may extend past the image (the outside is black)."""
    cx: float
    cy: float
    size: float

    @property
    def factor(self):
        return INPUT_SIZE / self.size

    def to_crop(self, uv):
        uv = np.asarray(uv, dtype=np.float64)
        return (uv - [self.cx - self.size / 2, self.cy - self.size / 2]) * self.factor

    def to_image(self, uv):
        uv = np.asarray(uv, dtype=np.float64)
        return uv / self.factor + [self.cx - self.size / 2, self.cy - self.size / 2]

    def image_to_crop_matrix(self):
        """2x3 affine: image pixel centres -> crop pixel centres (for cv2.warpAffine)."""
        f = self.factor
        x0, y0 = self.cx - self.size / 2, self.cy - self.size / 2
        # pixel centres: crop (u + 0.5) = f (x + 0.5 - x0)
        return np.array([[f, 0.0, f * (0.5 - x0) - 0.5], [0.0, f, f * (0.5 - y0) - 0.5]])

    def widened(self, factor):
        return CropBox(self.cx, self.cy, self.size * factor)

    def contains(self, uv):
        uv = np.asarray(uv, dtype=np.float64)
        half = self.size / 2
        return (np.abs(uv[..., 0] - self.cx) <= half) & (np.abs(uv[..., 1] - self.cy) <= half)


def crop_around(points_uv, margin=CROP_MARGIN, min_size=32.0):
    """The square crop around image points (the projected joints of a pose), `margin` x their box."""
    pts = np.asarray(points_uv, dtype=np.float64).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        raise FeatureInputError("no finite point to place the crop around")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    return CropBox(float(centre[0]), float(centre[1]), float(max(min_size, margin * (hi - lo).max())))


def whole_image_crop(width, height):
    return CropBox(width / 2.0, height / 2.0, float(max(width, height)))


def crop_image(image_bgr, box):
    """The model's input for one view: RGB float32 in [0, 1], INPUT_SIZE square, black outside the image."""
    img = np.asarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3:
        raise FeatureInputError(f"expected a colour image HxWx3, got shape {img.shape}")
    crop = cv2.warpAffine(img, box.image_to_crop_matrix(), (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_AREA
                          if box.factor < 1 else cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    crop = cv2.cvtColor(crop, cv2.COLOR_BGR2RGB).astype(np.float32)
    return crop / (np.float32(255.0) if img.dtype == np.uint8 or crop.max() > 1.5 else np.float32(1.0))


def mask_to_image(prob_crop, box, width, height):
    """A crop's mask probabilities -> the full image; NaN (unknown) outside the crop."""
    inverse = cv2.invertAffineTransform(box.image_to_crop_matrix())
    prob = cv2.warpAffine(np.asarray(prob_crop, np.float32), inverse, (width, height), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    # Pixels whose centre lies outside the square (the same test as CropBox.contains, per row and column).
    half = box.size / 2
    cols = np.abs(np.arange(width) + 0.5 - box.cx) <= half
    rows = np.abs(np.arange(height) + 0.5 - box.cy) <= half
    prob[~rows, :] = np.nan
    prob[:, ~cols] = np.nan
    return prob


def mask_at_size(prob_crop, box, image_size, size_wh):
    """A crop's mask probabilities sampled straight at the centres of a (width, height) grid laid over the
    whole image (a feature resolution): 0 outside the crop. Skips the full-resolution image, which for HD
    footage costs more than the model's look at the crop."""
    width, height = image_size
    fw, fh = size_wh
    sx, sy = fw / width, fh / height
    # grid pixel centre (u + 0.5) sits at image (u + 0.5) / sx, i.e. image pixel centre (u + 0.5) / sx - 0.5
    to_image = np.array([[1 / sx, 0.0, 0.5 / sx - 0.5], [0.0, 1 / sy, 0.5 / sy - 0.5], [0.0, 0.0, 1.0]])
    grid_to_crop = box.image_to_crop_matrix() @ to_image
    return cv2.warpAffine(np.asarray(prob_crop, np.float32), grid_to_crop, (int(fw), int(fh)),
                          flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0.0)


# ---------------------------------------------------------------------------------------- the model
class ViewEvidence:
    """One view's learned evidence, in the camera's full-resolution pixels.

    mask_prob     float32 HxW person probability; NaN where the crop did not look (unknown). Made from the
                  crop's probabilities on first use when the evidence comes from the model (`crop_prob`):
                  the tracker asks only for masks at its feature resolutions (mask_at).
    keypoints     (33, 2) landmark positions
    visibility    (33,) in [0, 1]: the landmark is in view and not occluded
    presence      the model's confidence that a person is in the crop
    box           where it looked; None: no evidence in this view this frame
    alternatives  (33, ALTERNATIVES, 3): second guesses per landmark from the heatmaps, (u, v) image pixels
                  and the gap in logits below the landmark's top peak; NaN rows where there is none.
                  None: not computed.
    clothes       the signature of the clothes the landmarks outline (core/evidence/appearance.py), or None
    """

    def __init__(self, mask_prob, keypoints, visibility, presence, box, alternatives=None, crop_prob=None,
                 image_size=None):
        if mask_prob is None and (crop_prob is None or box is None or image_size is None):
            raise FeatureInputError("ViewEvidence needs the full-resolution mask or the crop's mask, box and "
                                    "image size")
        self._mask_prob = mask_prob
        self.crop_prob = crop_prob
        self.image_size = tuple(image_size) if image_size is not None else tuple(mask_prob.shape[1::-1])
        self.keypoints = keypoints
        self.visibility = visibility
        self.presence = presence
        self.box = box
        self.alternatives = alternatives
        self.clothes = None  # the clothes under the landmarks (appearance.clothes_signature), once looked at

    @property
    def mask_prob(self):
        if self._mask_prob is None:
            self._mask_prob = mask_to_image(self.crop_prob, self.box, *self.image_size)
        return self._mask_prob

    @mask_prob.setter
    def mask_prob(self, value):
        self._mask_prob, self.crop_prob = value, None
        self.image_size = tuple(np.shape(value)[1::-1])

    @property
    def found(self):
        return self.box is not None and self.presence >= MIN_PRESENCE

    @property
    def mask(self):
        """bool HxW: person where the model says so; unknown counts as not person."""
        with np.errstate(invalid="ignore"):
            return np.nan_to_num(self.mask_prob, nan=0.0) >= MASK_THRESHOLD

    def mask_at(self, size_wh):
        """bool mask on a (width, height) grid over the image (a feature resolution): person where the
        model's probability at the grid pixel's centre reaches MASK_THRESHOLD."""
        size_wh = (int(size_wh[0]), int(size_wh[1]))
        if size_wh == self.image_size:
            return self.mask
        if self._mask_prob is None:
            return mask_at_size(self.crop_prob, self.box, self.image_size, size_wh) >= MASK_THRESHOLD
        return resize_mask(self.mask, size_wh)

    @property
    def known(self):
        return np.isfinite(self.mask_prob)

    @classmethod
    def empty(cls, width, height):
        return cls(np.full((height, width), np.nan, np.float32), np.full((N_LANDMARKS, 2), np.nan),
                   np.zeros(N_LANDMARKS), 0.0, None)


def model_path(name="full"):
    """The file of the landmark model `name` (a key of LANDMARK_MODEL_FILES)."""
    if name not in LANDMARK_MODEL_FILES:
        raise LearnedModelError(f"landmark model {name!r} is not one of {', '.join(LANDMARK_MODEL_FILES)}")
    return MODEL_PATH if name == "full" else MODELS_FOLDER / LANDMARK_MODEL_FILES[name]


def require_model(path=None):
    """The model file's path; a LearnedModelError naming the fix when it is missing."""
    path = Path(MODEL_PATH if path is None else path)
    if not path.is_file():
        raise LearnedModelError(f"the landmark model {path} is missing: it ships with the extension "
                                "(core/data/models/); reinstall the extension or restore that file, or choose "
                                "a likelihood without learned evidence (e.g. silh+edge)")
    return path


class LandmarkModel:
    """BlazePose landmarks + segmentation in OpenCV's DNN, batched over crops ('full' unless `path` is another
    model's file: model_path)."""

    def __init__(self, path=None):
        path = require_model(path)
        try:
            self.net = cv2.dnn.readNetFromTFLite(str(path))
        except cv2.error as exc:
            raise LearnedModelError(f"OpenCV could not load the landmark model {path}: {exc.err}; it needs "
                                    "OpenCV 4.9 or later with the TFLite importer") from exc
        self.net.setPreferableBackend(cv2.dnn.DNN_BACKEND_OPENCV)
        self.outputs = ["Identity", "Identity_1", "Identity_2", "Identity_3"]

    def infer(self, crops):
        """crops (N, 256, 256, 3) RGB in [0, 1] -> landmarks (N, 39, 5) raw, presence (N,), mask logits
        (N, 256, 256), heatmap logits (N, 39, 64, 64)."""
        crops = np.asarray(crops, dtype=np.float32)
        if crops.ndim != 4 or crops.shape[1:] != (INPUT_SIZE, INPUT_SIZE, 3):
            raise FeatureInputError(f"crops must be (N, {INPUT_SIZE}, {INPUT_SIZE}, 3); got {crops.shape}")
        self.net.setInput(np.ascontiguousarray(crops.transpose(0, 3, 1, 2)))  # OpenCV wants NCHW
        landmarks, presence, mask, heat = self.net.forward(self.outputs)
        n = len(crops)
        return (landmarks.reshape(n, -1, 5), presence.reshape(n).astype(np.float64),  # already a probability
                mask.reshape(n, INPUT_SIZE, INPUT_SIZE), heat.reshape(n, -1, HEATMAP_SIZE, HEATMAP_SIZE))

    def evidence(self, images, boxes):
        """One ViewEvidence per (image, box), one batched forward pass."""
        crops = np.stack([crop_image(img, box) for img, box in zip(images, boxes)])
        landmarks, presence, mask_logits, heat = self.infer(crops)
        out = []
        for img, box, lm, pres, logit, hm in zip(images, boxes, landmarks, presence, mask_logits, heat):
            h, w = img.shape[:2]
            kp = box.to_image(lm[:N_LANDMARKS, :2])
            vis = _sigmoid(lm[:N_LANDMARKS, 3]) * _sigmoid(lm[:N_LANDMARKS, 4])
            alternatives = heatmap_alternatives(hm[:N_LANDMARKS], lm[:N_LANDMARKS, :2])
            alternatives[..., :2] = box.to_image(alternatives[..., :2])
            out.append(ViewEvidence(None, kp, vis, float(pres), box, alternatives,
                                    crop_prob=_sigmoid(logit).astype(np.float32), image_size=(w, h)))
        return out


def heatmap_alternatives(heat, regressed, n=ALTERNATIVES, max_gap=ALTERNATIVE_MAX_GAP,
                         min_distance=ALTERNATIVE_MIN_DISTANCE):
    """Second guesses per landmark: heat (L, 64, 64) logits, regressed (L, 2) crop pixels -> (L, n, 3) of
    (u, v) crop pixels and the gap below the landmark's top logit, strongest first; NaN where none.

    A second guess is a local maximum of the heatmap (3 x 3 cells) within `max_gap` logits of the top one
    and at least `min_distance` crop pixels from the regressed point (which stands for the top peak).
    All landmarks at once (a tenth of the per-landmark loop's time, which ran for every view of every frame)."""
    heat = np.asarray(heat, dtype=np.float32)
    L, size = heat.shape[0], heat.shape[-1]
    out = np.full((L, n, 3), np.nan)
    # One dilation for all: the heatmaps stacked, a row of -inf between them (no neighbour across it).
    stacked = np.full((L, size + 1, size), -np.inf, np.float32)
    stacked[:, :size] = heat
    neighbourhood = cv2.dilate(stacked.reshape(-1, size), np.ones((3, 3), np.uint8)).reshape(L, size + 1, size)
    neighbourhood = neighbourhood[:, :size]
    top = heat.reshape(L, -1).max(axis=1)
    lms, rows, cols = np.nonzero((heat == neighbourhood) & (heat >= (top - max_gap)[:, None, None]))
    if len(lms) == 0:
        return out
    uv = _refined_peaks(heat, lms, rows, cols) * (INPUT_SIZE / size)  # cells (i + 0.5) x cell: crop pixels
    gap = top[lms] - heat[lms, rows, cols]
    far = np.linalg.norm(uv - np.asarray(regressed, dtype=np.float64)[lms], axis=1) >= min_distance
    lms, uv, gap = lms[far], uv[far], gap[far]
    order = np.lexsort((gap, lms))  # by landmark, strongest (smallest gap) first; ties keep the scan order
    lms, uv, gap = lms[order], uv[order], gap[order]
    rank = np.arange(len(lms)) - np.searchsorted(lms, lms)  # place within its landmark
    keep = rank < n
    out[lms[keep], rank[keep], :2] = uv[keep]
    out[lms[keep], rank[keep], 2] = gap[keep]
    return out


def _refined_peaks(h, i, rows, cols):
    """(N, 2) peak positions (x, y) in cells + 0.5, refined by a parabola through each axis's neighbours:
    peak n at cell (rows[n], cols[n]) of heatmap h[i[n]]."""
    size = h.shape[-1]

    def offset(lo, mid, hi):
        denom = lo - 2 * mid + hi
        return np.where(denom < 0, 0.5 * (lo - hi) / np.where(denom < 0, denom, -1.0), 0.0)

    r0, r1 = np.clip(rows - 1, 0, size - 1), np.clip(rows + 1, 0, size - 1)
    c0, c1 = np.clip(cols - 1, 0, size - 1), np.clip(cols + 1, 0, size - 1)
    dy = offset(h[i, r0, cols], h[i, rows, cols], h[i, r1, cols])
    dx = offset(h[i, rows, c0], h[i, rows, cols], h[i, rows, c1])
    return np.stack([cols + 0.5 + np.clip(dx, -0.5, 0.5), rows + 0.5 + np.clip(dy, -0.5, 0.5)], axis=1)


# ---------------------------------------------------------------------------------------- finding the person again
def person_blob_crop(foreground, min_area_fraction=0.002):
    """A crop on the tallest upright blob of a foreground mask (the person when the prediction lost it)."""
    fg = np.asarray(foreground, dtype=np.uint8)
    fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, np.ones((7, 7), np.uint8))
    n, _, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    best, best_score = None, 0.0
    for i in range(1, n):
        x, y, w, h, area = stats[i]
        if area < min_area_fraction * fg.size or h < 1.2 * w:  # people stand taller than wide
            continue
        if h * area > best_score:
            best, best_score = (x, y, w, h), h * area
    if best is None:
        return None
    x, y, w, h = best
    return crop_around([[x, y], [x + w, y + h]])


def locate(model, images, boxes, foreground=None, widen=1.6):
    """Evidence per view: the given crop; where the person is lost there, a wider crop; then a crop on
    the view's largest person-like foreground blob (`foreground(i)` -> bool mask of view i, asked only
    for such views); else the view has no evidence this frame."""
    evidence = model.evidence(images, boxes)
    retry = [i for i, ev in enumerate(evidence) if not ev.found]
    if retry:
        wider = model.evidence([images[i] for i in retry], [boxes[i].widened(widen) for i in retry])
        for i, ev in zip(retry, wider):
            if ev.found:
                evidence[i] = ev
    retry = [i for i, ev in enumerate(evidence) if not ev.found]
    blobs = {i: person_blob_crop(foreground(i)) for i in retry} if foreground is not None else {}
    blobs = {i: b for i, b in blobs.items() if b is not None}
    if blobs:
        found = model.evidence([images[i] for i in blobs], list(blobs.values()))
        for i, ev in zip(blobs, found):
            if ev.found:
                evidence[i] = ev
    for i, ev in enumerate(evidence):
        if not ev.found:
            h, w = images[i].shape[:2]
            evidence[i] = ViewEvidence.empty(w, h)
    return evidence
