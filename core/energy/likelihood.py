"""The tracker's energy V(x) = sum of weighted likelihood terms (paper eqs. 6-12, algorithms.md 7.1-7.6).

Terms (all unweighted values are normalised averages, O(1)):
  silh     binary XOR silhouette, per view #(T xor I) / area of the reference-pose template, mean over views (7a)
  silh_ch  Chamfer silhouette, per view 1/(2|T|) sum_T D_I + 1/(2|I|) sum_I min(D_T, 20 px), mean over views
           (7b, A11; the truncation is a DESIGN addition, see SILH_CH_CAP_PX); distances in capture-resolution
           pixels, so lambda does not change with the energy resolution [DESIGN]
  edge     binary edge, (1/Y) sum_v #(template part-boundary pixels not on an image edge), Y = sum_v boundary
           pixels of the reference pose (eq. 9, A10)
  edge_ch  Chamfer edge, like edge with the edge distance truncated at 20 px (x scale) divided by that cap,
           so it lies in [0, 1] like the binary term [DESIGN]
  color    per-part a/b 64-bin histograms vs the colour model, Bhattacharyya, w_s = part area share, parts with
           < 20 visible pixels (all views together) count as 1 (eq. 10, A13); model set at frame 1 and adapted
           with eq. 12 (sample-size weighted, M <- (1-lam) M + lam M_hat, A15)
  keypoint learned 2D landmarks (core/evidence/learned.py) against the projected rig points they stand for
           (core/evidence/keypoints.py): visibility-weighted robust distance in units of the person's size, each view's
           left/right pairs taken in whichever assignment fits, mean over the views with landmarks [DESIGN]
  anat     anatomical prior (core/energy/prior.py, eqs. 13-14)

The silhouette terms read the observed mask from background subtraction (mask="background", the paper) or
from the learned person mask (mask="learned"; the names starting with "l").

Energy resolution: at most ENERGY_SCALE = 0.5 of the capture (320x240 for 640x480) [DESIGN, measured]: a
forearm stays a few pixels wide there, and the cost follows the triangles, not the pixels, so a coarser image
saves nothing (docs/defaults.md, "ENERGY_SCALE").

Default weights (LIKELIHOODS; lambda_anat = 2.0 in all [SEED] but the product's default lsilh+edge+kp: 1.0):
  name            silh  silh_ch  edge  edge_ch  color  adaptation
  "silh"          30    -        -     -        -      -      silh alone: lambda not published, same as s+e [DESIGN]
  "silh+edge"     30    -        2     -        -      -      only lambda_silh >= 25, lambda_edge >= 1.6 [SEED]
                                                              -> [DESIGN]
  "silh+edgech"   30    -        -     2        -      -      as above [DESIGN]
  "silhch+color"  -     2        -     -        40     0.2    all [SEED] (Maria1 adaptation 0.2, Maria2 0.3, HumanEva 0)
  "silhch"        -     2        -     -        -      -      lambda as in s^Ch + c [SEED value reused, DESIGN]
  learned evidence: "lsilh+edge" (30, edge 2, learned mask), "silh+edge+kp" and "lsilh+edge+kp" (the same
  plus keypoint 20), "lsilh+kp" (30, keypoint 20), "kp" (keypoint 20) [DESIGN]
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, fields

import cv2
import numpy as np

from .. import render
from ..evidence.learned import CROP_MARGIN
from ..evidence.view_features import EDGE_DT_CAP_PX, distance_to_mask, resize_mask
from ..evidence.keypoints import KeypointTargets, keypoint_energy, rig_keypoints
from ..render import reference as render_reference

ENERGY_SCALE = 0.5
# The person's joints should span about this many energy pixels (energy_scale_for): at most 0.5 x the sample
# scenes' 640x480 footage, where every figure in docs/measurements.md was measured [DESIGN].
ENERGY_PERSON_PX = 120.0
# ... and about this many for the local fit after the search (TrackingSettings.refine_scale): the rims of
# forearms and shins are only a few pixels wide at 120, and the local fit alone costs little more at 240
# (docs/defaults.md, "REFINE_PERSON_PX").
REFINE_PERSON_PX = 240.0
# The Chamfer silhouette's second sum counts each observed pixel's distance to the model up to this many
# capture pixels [DESIGN]: untruncated, foreground far from the body (a sliding box, a swinging lamp) pulls the
# model towards it; truncated, it adds a constant (docs/defaults.md, "SILH_CH_CAP_PX").
SILH_CH_CAP_PX = 20.0
KEYPOINT_WEIGHT = 20.0  # lambda_kp [DESIGN] (docs/defaults.md, "KEYPOINT_WEIGHT")
# lambda_anat of the product's default likelihood (lsilh+edge+kp) [DESIGN, measured]: half the paper's 2, which
# pulled the search towards common poses once the landmarks hold the limbs; the paper's likelihoods and the other
# learned ones keep 2 (docs/defaults.md, "DEFAULT_LIKELIHOOD_ANAT_WEIGHT").
DEFAULT_LIKELIHOOD_ANAT_WEIGHT = 1.0
MIN_PART_PIXELS = 20  # colour: parts seen less than this (all views together) contribute (1 - BC) = 1
TERM_NAMES = ("silh", "silh_ch", "edge", "edge_ch", "color", "keypoint", "anat")
NON_IMAGE_TERMS = ("keypoint", "anat")  # computed from joints, not from the rasterised model
MASK_SOURCES = ("background", "learned")


class LikelihoodError(ValueError):
    """The energy model was set up or called with unusable input (wrong sizes, missing frame or model)."""


@dataclass(frozen=True)
class LikelihoodWeights:
    silh: float = 0.0
    silh_ch: float = 0.0
    edge: float = 0.0
    edge_ch: float = 0.0
    color: float = 0.0
    keypoint: float = 0.0
    anat: float = 0.0
    adaptation: float = 0.0  # colour model adaptation speed lambda of eq. 12
    # Where the silhouette terms' observed mask comes from: background subtraction (the paper) or the
    # learned person mask (core/evidence/learned.py).
    mask: str = "background"

    def __post_init__(self):
        if self.mask not in MASK_SOURCES:
            raise LikelihoodError(f"mask must be one of {MASK_SOURCES}; got {self.mask!r}")

    @property
    def needs_learned_evidence(self):
        return self.mask == "learned" or self.keypoint != 0

    def active_terms(self):
        return [f.name for f in fields(self) if f.name in TERM_NAMES and getattr(self, f.name) != 0]


LIKELIHOODS: dict[str, LikelihoodWeights] = {
    "silh": LikelihoodWeights(silh=30.0, anat=2.0),
    "silh+edge": LikelihoodWeights(silh=30.0, edge=2.0, anat=2.0),
    "silh+edgech": LikelihoodWeights(silh=30.0, edge_ch=2.0, anat=2.0),
    "silhch+color": LikelihoodWeights(silh_ch=2.0, color=40.0, anat=2.0, adaptation=0.2),
    "silhch": LikelihoodWeights(silh_ch=2.0, anat=2.0),
    # Learned evidence (core/evidence/learned.py): "l" silhouettes use the learned person mask,
    # "kp" adds the 2D keypoint term (core/evidence/keypoints.py).
    "lsilh+edge": LikelihoodWeights(silh=30.0, edge=2.0, anat=2.0, mask="learned"),
    "silh+edge+kp": LikelihoodWeights(silh=30.0, edge=2.0, keypoint=KEYPOINT_WEIGHT, anat=2.0),
    "lsilh+edge+kp": LikelihoodWeights(silh=30.0, edge=2.0, keypoint=KEYPOINT_WEIGHT,
                                       anat=DEFAULT_LIKELIHOOD_ANAT_WEIGHT, mask="learned"),
    "lsilh+kp": LikelihoodWeights(silh=30.0, keypoint=KEYPOINT_WEIGHT, anat=2.0, mask="learned"),
    "kp": LikelihoodWeights(keypoint=KEYPOINT_WEIGHT, anat=2.0),
}


def resolve_weights(weights) -> LikelihoodWeights:
    if isinstance(weights, LikelihoodWeights):
        return weights
    if isinstance(weights, str):
        if weights not in LIKELIHOODS:
            raise LikelihoodError(f"unknown likelihood {weights!r}; choose one of {sorted(LIKELIHOODS)} or pass "
                                  "a LikelihoodWeights")
        return LIKELIHOODS[weights]
    raise LikelihoodError(f"weights must be a LikelihoodWeights or a name in {sorted(LIKELIHOODS)}; got {weights!r}")


def energy_scale_for(body, cameras, pose, person_px=ENERGY_PERSON_PX, largest=ENERGY_SCALE):
    """The energy resolution for a capture: the person (the height of the projected joints of `pose`,
    median over the views) about `person_px` pixels tall, never finer than `largest` x the capture.

    The cost and the accuracy of the image terms follow the person's size in pixels, not the footage's:
    the sample scenes (640x480, joints 150-280 px tall) stay at 0.5; 1080x1920 footage of a person
    filling the frame drops to about 0.1 instead of costing 25 times as much."""
    joints = body.joint_positions(np.atleast_2d(pose))[0]
    heights = [np.ptp(cam.project(joints)[:, 1]) for cam in cameras]
    height = float(np.median(heights))
    if not np.isfinite(height) or height <= 0:
        return largest
    return float(min(largest, max(person_px / height, 0.05)))


def default_pose_at(body, pose):
    """The default (undeformed) pose placed at `pose`'s root position and orientation: the pose whose
    projected area and boundary length normalise the silhouette and edge terms."""
    ref = body.default_pose()
    pose = np.asarray(pose, dtype=np.float64).reshape(-1)
    root = np.concatenate([body.translation_dofs, body.root_rotation_dofs]).astype(np.int64)
    ref[root] = pose[root]
    return ref


# ---------------------------------------------------------------------------------------- frame features
def _resample_view(feat, width, height, scale, view):
    """ViewFeatures at any resolution -> the five arrays FrameTargets needs at (height, width)."""
    sil = np.asarray(feat.silhouette, dtype=bool)
    cap = EDGE_DT_CAP_PX * scale
    if sil.shape == (height, width):
        edges = np.asarray(feat.edges, dtype=bool)
        sil_dt = np.asarray(feat.silhouette_dt, dtype=np.float64)
        edge_dt = np.minimum(np.asarray(feat.edge_dt, dtype=np.float64), cap)
        ab = np.asarray(feat.lab_ab, dtype=np.float32)
    else:
        h0, w0 = sil.shape
        if abs(w0 / h0 - width / height) > 0.02 * width / height:
            raise LikelihoodError(f"view {view}: features are {w0}x{h0}, which is not the camera's aspect "
                                  f"({width}x{height} at the energy resolution); compute the features from this "
                                  "camera's images")
        shrink = w0 > width
        sil = resize_mask(sil, (width, height))
        sil_dt = distance_to_mask(sil).astype(np.float64)
        edge_src = np.asarray(feat.edges, dtype=np.float32)
        if shrink:  # an energy pixel is on an edge if any capture pixel under it is
            edges = cv2.resize(edge_src, (width, height), interpolation=cv2.INTER_AREA) > 0
        else:
            edges = cv2.resize(edge_src, (width, height), interpolation=cv2.INTER_NEAREST) > 0
        edge_dt = np.minimum(distance_to_mask(edges).astype(np.float64), cap)
        ab = cv2.resize(np.asarray(feat.lab_ab, dtype=np.float32), (width, height),
                        interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    if ab.shape != (height, width, 2):
        raise LikelihoodError(f"view {view}: lab_ab has shape {ab.shape}; expected {(height, width, 2)}")
    return sil, sil_dt, ~edges, edge_dt, render.ab_to_bins(ab)


def frame_targets(features, cameras, scale):
    """List of ViewFeatures (one per camera, any resolution) -> FrameTargets at the energy cameras' size."""
    if len(features) != len(cameras):
        raise LikelihoodError(f"got features for {len(features)} views but the model has {len(cameras)} cameras; "
                              "pass one ViewFeatures per camera, in camera order")
    H = max(c.height for c in cameras)
    W = max(c.width for c in cameras)
    C = len(cameras)
    sil = np.zeros((C, H, W), np.uint8)
    sil_dt = np.zeros((C, H, W))
    edge_off = np.zeros((C, H, W), np.uint8)
    edge_dt = np.zeros((C, H, W))
    bins = np.zeros((C, H, W, 2), np.uint8)
    for c, (feat, cam) in enumerate(zip(features, cameras)):
        h, w = cam.height, cam.width
        sil[c, :h, :w], sil_dt[c, :h, :w], edge_off[c, :h, :w], edge_dt[c, :h, :w], bins[c, :h, :w] = \
            _resample_view(feat, w, h, scale, c)
    return render.FrameTargets([c.width for c in cameras], [c.height for c in cameras], sil, sil_dt, edge_off,
                               edge_dt, bins, chamfer_cap=SILH_CH_CAP_PX * scale)


# ---------------------------------------------------------------------------------------- colour helpers
def bhattacharyya_cost(model_hist, counts):
    """Per-part colour cost (P,S): sum_c (1 - sum_k sqrt(h_k h~_k)) / C, and 1 for parts with too few pixels.

    model_hist (S,2,K) normalised; counts (P,S,2,K) pixel counts of the pose's visible parts.
    """
    counts = np.asarray(counts, dtype=np.float64)
    n = counts[..., 0, :].sum(axis=-1)  # (P,S) pixels per part
    with np.errstate(invalid="ignore", divide="ignore"):
        h = counts / n[..., None, None]
    bc = np.sqrt(np.nan_to_num(h) * model_hist[None]).sum(axis=-1)  # (P,S,2)
    cost = np.clip(1.0 - bc, 0.0, 1.0).mean(axis=-1)  # rounding can push BC a hair above 1
    return np.where(n < MIN_PART_PIXELS, 1.0, cost)


def adapt_histograms(model_hist, model_count, new_hist, new_count, lam):
    """Eq. 12 with the sample sizes, then M <- (1-lam) M + lam M_hat (A15). Arrays (S,2,K) and (S,)."""
    a = (1.0 - lam) * np.asarray(model_count, dtype=np.float64)
    b = lam * np.asarray(new_count, dtype=np.float64)
    den = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        mixed = (a[:, None, None] * model_hist + b[:, None, None] * new_hist) / den[:, None, None]
    hist = np.where(den[:, None, None] > 0, mixed, model_hist)
    return hist, a + b


# ---------------------------------------------------------------------------------------- the model
class EnergyModel:
    """V(x) for batches of poses against one frame's features. See the module docstring for the terms."""

    def __init__(self, body, proxy, cameras, weights, prior=None, scale: float = ENERGY_SCALE, backend="auto",
                 cull="auto", landmarks="full"):
        if not cameras:
            raise LikelihoodError("the energy model needs at least one camera")
        if not 0 < scale <= 1:
            raise LikelihoodError(f"energy scale must be in (0, 1] of the capture resolution; got {scale}")
        self.body = body
        self.proxy = proxy
        self.capture_cameras = list(cameras)
        self.scale = float(scale)
        self.cameras = [c.scaled(self.scale) for c in cameras]
        self.weights = resolve_weights(weights)
        self.prior = prior
        self.backend = render.resolve_backend(backend)
        self.faces = np.ascontiguousarray(proxy.faces, dtype=np.int64)
        self.face_label = (np.asarray(proxy.face_part) + 1).astype(np.int16)
        self.n_parts = len(proxy.part_names)
        self.part_weights = np.asarray(proxy.part_area_share, dtype=np.float64)
        if self.weights.anat and prior is None:
            warnings.warn("the likelihood asks for the anatomical prior (lambda_anat != 0) but none was given; "
                          "V_anat is left out", RuntimeWarning)
        self._cull_request = cull
        self.cull = 0 if cull == "auto" else int(cull)
        self.targets = None
        self.keypoints = None   # KeypointTargets of the current frame (learned landmarks)
        self.landmarks = landmarks  # the landmark model whose placement the rig points follow (keypoints.py)
        self._rig_points = None
        self.color_model = None  # (S,2,K) normalised histograms
        self.color_count = None  # (S,) sample sizes M
        self.view_weights = None  # (C,) 0/1 per view this frame; None: every view counts (the paper's terms)
        self.set_reference_pose(body.default_pose())

    def set_view_weights(self, weights):
        """Which views the image terms listen to this frame (0 = left out, e.g. the person is outside
        that picture); None or all ones: every view, exactly the paper's terms."""
        if weights is None or np.all(np.asarray(weights) == 1):
            self.view_weights = None
            return
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape != (len(self.cameras),) or not np.all(w >= 0) or w.sum() <= 0:
            raise LikelihoodError(f"view weights must be {len(self.cameras)} non-negative numbers, not all zero; "
                                  f"got {weights!r}")
        self.view_weights = w

    def _over_views(self, per_view, mean=True):
        """(P,C) -> (P,): mean (or sum) over the views, weighted by view_weights when some are left out."""
        if self.view_weights is None:
            return per_view.mean(axis=1) if mean else per_view.sum(axis=1)
        total = per_view @ self.view_weights
        return total / self.view_weights.sum() if mean else total * len(self.cameras) / self.view_weights.sum()

    # ---- geometry ----------------------------------------------------------------------------
    def _check_poses(self, poses):
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        if poses.ndim != 2 or poses.shape[1] != self.body.n_dof:
            raise LikelihoodError(f"poses must have shape (P, {self.body.n_dof}) for this body's DOF; "
                                  f"got {poses.shape}")
        return poses

    def project(self, poses):
        """(P,D) -> pixels (P,C,V,2) and depths (P,C,V) of the proxy vertices at the energy resolution."""
        vertices = self.proxy.deform(self.body, self._check_poses(poses))
        return render.project_views(vertices, self.cameras)

    def _blank_targets(self):
        C = len(self.cameras)
        H = max(c.height for c in self.cameras)
        W = max(c.width for c in self.cameras)
        z = np.zeros((C, H, W))
        return render.FrameTargets([c.width for c in self.cameras], [c.height for c in self.cameras],
                                   z.astype(np.uint8), z, z.astype(np.uint8), z, np.zeros((C, H, W, 2), np.uint8))

    def _choose_cull(self, uv, z):
        """Back-face culling only when it leaves the silhouettes of the reference pose unchanged (<= 0.5%)."""
        full = [render.rasterize(uv[0, c], z[0, c], self.faces, self.face_label, cam.width, cam.height) > 0
                for c, cam in enumerate(self.cameras)]
        area = sum(int(f.sum()) for f in full)
        for sign in (-1, 1):
            diff = sum(int(((render.rasterize(uv[0, c], z[0, c], self.faces, self.face_label, cam.width,
                                              cam.height, sign) > 0) != full[c]).sum())
                       for c, cam in enumerate(self.cameras))
            if area and diff <= 0.005 * area:
                return sign
        return 0

    def set_reference_pose(self, pose):
        """Normalisers from `pose`: per-view template area (silh) and total boundary pixels Y (edge).

        The paper uses the undeformed mesh: pass `default_pose_at(body, initial_pose)`.
        """
        uv, z = self.project(pose)
        if self._cull_request == "auto":
            self.cull = self._choose_cull(uv, z)
        stats, _ = render.statistics(uv, z, self.faces, self.face_label, self._blank_targets(), False, 0, self.cull,
                                     backend="numpy")
        self.reference_area = stats[0, :, render.TEMPLATE].copy()
        self.reference_boundary = float(stats[0, :, render.BOUNDARY].sum())

    def set_frame(self, features, evidence=None):
        """One ViewFeatures per camera (capture resolution or already at the energy resolution), and the
        learned evidence (one ViewEvidence per camera) when the likelihood uses keypoints."""
        self.targets = frame_targets(features, self.cameras, self.scale)
        if evidence is not None:
            if len(evidence) != len(self.cameras):
                raise LikelihoodError(f"got learned evidence for {len(evidence)} views; the model has "
                                      f"{len(self.cameras)} cameras")
            self.keypoints = KeypointTargets.from_evidence(evidence, self.rig_points, CROP_MARGIN)
        elif self.weights.keypoint:
            raise LikelihoodError("the likelihood has a keypoint term: pass the frame's learned evidence "
                                  "to set_frame(features, evidence)")

    @property
    def rig_points(self):
        if self._rig_points is None:
            self._rig_points = rig_keypoints(self.body, self.landmarks)
        return self._rig_points

    def project_rig_points(self, poses):
        """(P,D) -> (P,C,K,2) capture pixels of the landmarks' rig points."""
        points = self.rig_points.world(self.body, self._check_poses(poses))
        P, K = points.shape[:2]
        flat = points.reshape(-1, 3)
        return np.stack([cam.project(flat).reshape(P, K, 2) for cam in self.capture_cameras], axis=1)

    # ---- statistics and terms ------------------------------------------------------------------
    def _statistics(self, poses, need_chamfer, need_color):
        if self.targets is None:
            raise LikelihoodError("no frame: call set_frame(features) before evaluating poses")
        poses = self._check_poses(poses)
        return render.measure_poses(self.body, self.proxy, poses, self.cameras, self.faces, self.face_label,
                                    self.targets, need_chamfer, self.n_parts if need_color else 0, self.cull,
                                    self.backend)

    def _check_reference(self, which):
        if which == "silh" and np.any(self.reference_area <= 0):
            bad = [self.cameras[c].name for c in np.nonzero(self.reference_area <= 0)[0]]
            raise LikelihoodError(f"the reference pose is not visible in camera(s) {bad}: call "
                                  "set_reference_pose(default_pose_at(body, initial_pose)) with the subject in view")
        if which == "edge" and self.reference_boundary <= 0:
            raise LikelihoodError("the reference pose has no boundary pixels in any view: call "
                                  "set_reference_pose(default_pose_at(body, initial_pose)) with the subject in view")

    def terms(self, poses, names=None, weights=None):
        """Unweighted term values {name: (P,)}; default: the terms with a non-zero weight (in `weights`, by
        default the model's)."""
        explicit = names is not None
        weights = self.weights if weights is None else weights
        names = list(weights.active_terms() if names is None else names)
        unknown = [n for n in names if n not in TERM_NAMES]
        if unknown:
            raise LikelihoodError(f"unknown term(s) {unknown}; terms are {TERM_NAMES}")
        if "anat" in names and self.prior is None:
            if explicit:
                raise LikelihoodError("the anat term needs a prior: pass prior=AnatomicalPrior(...)")
            names.remove("anat")
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        out = {}
        image_terms = [n for n in names if n not in NON_IMAGE_TERMS]
        if image_terms:
            if "color" in names and self.color_model is None:
                raise LikelihoodError("the colour term needs a colour model: call init_color_model(initial_pose) "
                                      "after set_frame on the first frame")
            stats, hist = self._statistics(poses, "silh_ch" in names, "color" in names)
            for n in image_terms:
                out[n] = getattr(self, f"_term_{n}")(stats, hist)
        if "keypoint" in names:
            if self.keypoints is None:
                raise LikelihoodError("the keypoint term needs the frame's learned evidence: "
                                      "call set_frame(features, evidence)")
            out["keypoint"] = keypoint_energy(self.project_rig_points(poses), self.keypoints, self.rig_points.swap)
        if "anat" in names:
            out["anat"] = self.prior.energy(poses)
        return out

    def __call__(self, poses, weights=None):
        """V(x) for poses (P,D) -> (P,); the same as P single calls. `weights`: LikelihoodWeights to use instead
        of the model's (the first frame's search leaves colour out: its model is made from that search)."""
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        weights = self.weights if weights is None else weights
        total = np.zeros(len(poses))
        for name, value in self.terms(poses, weights=weights).items():
            total += getattr(weights, name) * value
        return total

    def _term_silh(self, stats, hist):
        self._check_reference("silh")
        n_obs = self.targets.observed_count[None, :]
        xor = stats[..., render.TEMPLATE] + n_obs - 2 * stats[..., render.OVERLAP]
        return self._over_views(xor / self.reference_area[None, :])

    def _term_silh_ch(self, stats, hist):
        n_t = stats[..., render.TEMPLATE]
        n_obs = np.broadcast_to(self.targets.observed_count[None, :].astype(np.float64), n_t.shape)
        diag = np.hypot(self.targets.widths, self.targets.heights)[None, :].astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            first = np.where(n_t > 0, stats[..., render.SUM_DI] / (2 * n_t), 0.0)
            far = np.minimum(diag, self.targets.chamfer_cap)  # no template: every observed pixel at the cap
            second = np.where(n_t > 0, stats[..., render.SUM_DT] / (2 * n_obs), 0.5 * far)
        second = np.where(n_obs > 0, second, 0.0)
        return self._over_views((first + second) / self.scale)

    def _term_edge(self, stats, hist):
        self._check_reference("edge")
        return self._over_views(stats[..., render.BOUNDARY_OFF], mean=False) / self.reference_boundary

    def _term_edge_ch(self, stats, hist):
        self._check_reference("edge")
        cap = EDGE_DT_CAP_PX * self.scale
        return self._over_views(stats[..., render.SUM_EDGE_DT], mean=False) / (cap * self.reference_boundary)

    def _term_color(self, stats, hist):
        seen = hist.sum(axis=1) if self.view_weights is None else np.tensordot(hist, self.view_weights, axes=([1], [0]))
        cost = bhattacharyya_cost(self.color_model, seen)
        return cost @ self.part_weights

    # ---- colour model ----------------------------------------------------------------------------
    def part_histograms(self, pose):
        """(S,2,K) normalised a/b histograms of the visible parts at `pose` (all views) and (S,) pixel counts."""
        stats, hist = self._statistics(pose, False, True)
        counts = hist[0].sum(axis=0).astype(np.float64)  # (S,2,K)
        n = counts[:, 0].sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            h = np.where(n[:, None, None] > 0, counts / n[:, None, None], 0.0)
        return h, n

    def init_color_model(self, pose):
        """Colour model H^(s,c) and sample sizes M^(s) from the current frame at `pose` (frame 1)."""
        self.color_model, self.color_count = self.part_histograms(pose)

    def adapt_color_model(self, pose, lam=None):
        """Eq. 12: blend the model with the current frame's histograms at the estimate `pose`."""
        lam = self.weights.adaptation if lam is None else float(lam)
        if not 0 <= lam <= 1:
            raise LikelihoodError(f"colour adaptation lambda must be in [0, 1]; got {lam}")
        if self.color_model is None:
            raise LikelihoodError("no colour model to adapt: call init_color_model(initial_pose) first")
        if lam == 0:
            return
        new_hist, new_count = self.part_histograms(pose)
        self.color_model, self.color_count = adapt_histograms(self.color_model, self.color_count, new_hist,
                                                              new_count, lam)

    # ---- overlays --------------------------------------------------------------------------------
    def render(self, pose, view, full_resolution=False):
        """(labels, silhouette, boundary) of `pose` in camera `view` via the reference rasteriser,
        at the energy resolution or (full_resolution=True) at the capture resolution."""
        cam = (self.capture_cameras if full_resolution else self.cameras)[view]
        vertices = self.proxy.deform(self.body, np.atleast_2d(pose))
        uv, z = render.project_views(vertices, [cam])
        return render_reference.render_view(uv[0, 0], z[0, 0], self.faces, self.face_label, cam.width, cam.height,
                                            self.cull)
