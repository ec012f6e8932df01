"""Refine the actor's proportions against the person masks of the calibration frames.

The landmark fit (core/actor/landmark_fit.py) places the body where BlazePose's points are; where those points
sit off the joints (a wrist landmark short of the wrist, hip landmarks inside the hip joints) the segment
comes out short or long, differently for different motions. The masks see the whole outline instead: a
longer forearm moves the hand's outline, wider hips move the thighs'. This step holds the fitted poses and
searches the segment factors (symmetric or sided, as fitted) for the scaled body whose rendered silhouettes
best match the masks: the XOR of model and mask in every view of every frame, each view's count divided by
the model's own area there (the `silh` term of core/energy/likelihood.py), summed over frames. A pattern search in
log-factor steps of 4 % down to 0.5 %: the XOR count is piecewise constant in the factors, so no gradient.
A weak pull towards the landmark fit keeps segments the outline barely shows (the neck inside the head and
shoulders) where the landmarks put them.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .. import render
from .proportions import Proportions, scaled_body, segment_lengths

STEPS = (0.04, 0.02, 0.01, 0.005)  # log-factor steps of the pattern search, coarse to fine
# Cost per squared log-factor departure from the landmark fit: a tie-breaker where the masks are flat. A 3 %
# departure costs 2e-5, far less than a length the masks see moves their mismatch (docs/defaults.md,
# "PULL_TO_LANDMARKS").
PULL_TO_LANDMARKS = 0.02
MIN_MASK_PIXELS = 50   # a view whose mask has fewer pixels shows no person: left out for that frame
MAX_ROUNDS = 12        # moves per step size
# The segments the masks refine; the others keep the landmark fit's length. Left free on every segment the masks
# narrowed the shoulders and lengthened feet and shins: a shoe's outline on the floor, or shoulders beside hanging
# arms, do not measure those lengths (docs/defaults.md, "SILHOUETTE_SEGMENTS").
SILHOUETTE_SEGMENTS = ("forearm", "hip_width")
ROUNDS = 3               # pose refits (ICP on the masks with the current body), each followed by a factor search
# How far the masks may move a segment from the landmark fit (log factor): a little past the landmarks' own
# misstatements; where the masks' optimum lies at this bound they do not pin the length down, and the segment
# keeps the landmark fit's length (docs/defaults.md, "MAX_DEPARTURE").
MAX_DEPARTURE = float(np.log(1.12))


@dataclasses.dataclass
class SilhouetteRefinement:
    proportions: Proportions
    cost_before: float   # mean per frame-view XOR / model area with the landmark fit's proportions (final poses)
    cost_after: float
    evaluations: int
    poses: np.ndarray    # (F,D) the poses the factors were searched with
    kept: list = dataclasses.field(default_factory=list)  # segments left at the landmark fit (optimum at the bound)


def _proxy_body(subject, proxy):
    """The subject's skeleton with the proxy's skin: scaled_body then scales the proxy the tracker renders."""
    from ..body.model import Body

    return Body(subject.skeleton, subject.dofs, proxy.vertices, proxy.faces, proxy.weights, subject.root_bone,
                subject.roles, subject.preset)


def _targets(masks, cameras):
    C = len(cameras)
    H = max(c.height for c in cameras)
    W = max(c.width for c in cameras)
    sil = np.zeros((C, H, W), np.uint8)
    for c, (m, cam) in enumerate(zip(masks, cameras)):
        m = np.asarray(m, bool)
        if m.shape != (cam.height, cam.width):
            raise ValueError(f"mask {c} is {m.shape[1]}x{m.shape[0]}; camera {cam.name} is {cam.width}x{cam.height}")
        sil[c, :cam.height, :cam.width] = m
    z = np.zeros((C, H, W))
    return render.FrameTargets([c.width for c in cameras], [c.height for c in cameras], sil, z,
                               np.zeros((C, H, W), np.uint8), z, np.zeros((C, H, W, 2), np.uint8))


class SilhouetteCost:
    """XOR / model area per frame and view for many candidate proportions at once (one batch per frame)."""

    def __init__(self, subject, proxy, cameras, masks, poses, backend="auto"):
        self.base = _proxy_body(subject, proxy)
        self.faces = np.ascontiguousarray(proxy.faces, np.int64)
        self.label = (np.asarray(proxy.face_part) + 1).astype(np.int16)
        self.cameras = list(cameras)
        self.poses = np.asarray(poses, float)
        self.targets = [_targets(m, self.cameras) for m in masks]
        counts = np.array([t.observed_count for t in self.targets], float)  # (F,C)
        self.views = counts >= MIN_MASK_PIXELS
        self.backend = render.cpu_backend(backend)
        self.evaluations = 0

    def __call__(self, candidates):
        """candidates: list of Proportions -> (K,) mean XOR / model area over the frame-views with a mask."""
        bodies = [scaled_body(self.base, p) for p in candidates]
        total = np.zeros(len(bodies))
        for f, (pose, targets) in enumerate(zip(self.poses, self.targets)):
            verts = np.concatenate([b.deform(pose[None], None, b.vertices, b.weights, b.unweighted)
                                    for b in bodies])  # (K,V,3)
            stats, _ = render.measure_vertices(verts, self.cameras, self.faces, self.label, targets, False, 0, 0,
                                            self.backend)
            area = np.maximum(stats[..., render.TEMPLATE], 1.0)
            xor = stats[..., render.TEMPLATE] + targets.observed_count[None] - 2 * stats[..., render.OVERLAP]
            total += (xor / area)[:, self.views[f]].sum(axis=1)
        self.evaluations += len(bodies)
        return total / max(1, int(self.views.sum()))


def _with(keys, z, overall):
    return Proportions(dict(zip(keys, np.exp(z))), overall)


def refit_poses(body, proxy, cameras, masks, poses, keypoints=None, resolution=1.0, landmarks="full"):
    """Every frame's pose fitted to its masks (and its landmarks, as the tracker's local fit weighs them) by
    ICP with `body`: what the tracker's refinement would make of these frames with that body.
    keypoints: per frame KeypointTargets at the cameras' resolution, or None; resolution: the masks' scale
    over the tracker's energy resolution (IcpSettings.at_resolution); landmarks: the landmark model that gave them."""
    from ..evidence.keypoints import rig_keypoints
    from ..optimizers import PoseSpace
    from ..optimizers.icp import IcpProblem, IcpSettings, IcpSolver

    space = PoseSpace.with_default_scale(body.lower, body.upper, body.dof_names,
                                         np.isin(np.arange(body.n_dof), body.translation_dofs))
    settings = IcpSettings().at_resolution(resolution)
    rig = rig_keypoints(body, landmarks) if keypoints is not None else None
    out = []
    for f, (pose, frame_masks) in enumerate(zip(np.asarray(poses, float), masks)):
        problem = IcpProblem(body=body, proxy=proxy, cameras=list(cameras), silhouettes=list(frame_masks),
                             keypoints=None if keypoints is None else keypoints[f], rig_points=rig)
        out.append(IcpSolver(problem, space, settings).fit(pose).pose)
    return np.array(out)


def refine_proportions(subject, proxy, cameras, masks, poses, proportions, backend="auto", steps=STEPS,
                       pull=PULL_TO_LANDMARKS, log=None, rounds=0, keypoints=None, resolution=1.0,
                       segments=None, landmarks="full"):
    """Search the segment factors of `proportions` (the landmark fit) against the masks.

    cameras: the capture's cameras at the masks' resolution (Camera.scaled); masks: per frame a list of one
    bool mask per camera; poses (F,D): the fitted poses of those frames. Returns a SilhouetteRefinement.
    The overall factor (head, hands, the skin's girth) stays the landmark fit's: left free, a segment would
    grow to fatten the whole body where a mask is wider than the person (shadows, loose clothes).
    segments: the segment names searched (None: all; the others keep their factor); rounds: pose refits by
    ICP (keypoints, resolution, landmarks: see refit_poses), each followed by a search; 0 holds `poses`."""
    log = log or (lambda msg: None)
    keys = list(proportions.factors)
    z0 = np.log([proportions.factors[k] for k in keys])
    overall = proportions.overall
    free = np.array([segments is None or k in segments or k[2:] in segments for k in keys])
    z, evaluations = z0.copy(), 0
    for _ in range(max(1, rounds)):
        if rounds:  # the poses the masks want for the current body, then the body for those poses
            poses = refit_poses(*scaled_proxy(subject, proxy, _with(keys, z, overall)), cameras, masks, poses,
                                keypoints, resolution, landmarks)
        cost = SilhouetteCost(subject, proxy, cameras, masks, poses, backend)

        def objective(zs, cost=cost):
            zs = np.array([np.where(free, v, z0) for v in zs])
            outside = (np.abs(zs - z0) > MAX_DEPARTURE + 1e-9).any(axis=1)
            value = cost([_with(keys, v, overall) for v in zs]) + pull * np.sum(np.square(zs - z0), axis=1)
            return np.where(outside, np.inf, value)

        z = np.where(free, _pattern_search(objective, z, steps, log, free), z0)
        evaluations += cost.evaluations
    at_bound = free & (np.abs(z - z0) > MAX_DEPARTURE - min(steps) - 1e-9)
    for i in np.nonzero(at_bound)[0]:
        log(f"silhouette refinement: the masks' optimum for {keys[i]} lies at the bound "
            f"(x{np.exp(z[i] - z0[i]):.3f} of the landmark fit): keeping the landmark fit's length")
    z = np.where(at_bound, z0, z)
    refined = _with(keys, z, overall)
    before, after = cost([proportions, refined])
    return SilhouetteRefinement(refined, float(before), float(after), evaluations, poses,
                                [keys[i] for i in np.nonzero(at_bound)[0]])


def _pattern_search(objective, z, steps, log, free):
    """Minimise objective (a batch of points -> values) from z: +-step on each free coordinate, coarse to fine."""
    best = float(objective([z])[0])
    n = len(z)
    axes = np.nonzero(free)[0]
    for step in steps:
        for _ in range(MAX_ROUNDS):
            trials = [z + s * step * np.eye(n)[i] for i in axes for s in (1, -1)]
            values = objective(trials)
            gains = best - values
            if gains.max() <= 0:
                break
            # each coordinate's better direction when it helps, all together; else the single best move
            move = np.zeros(n)
            for j, i in enumerate(axes):
                g = gains[2 * j:2 * j + 2]
                if g.max() > 0:
                    move[i] = step * (1 if g[0] >= g[1] else -1)
            combined = float(objective([z + move])[0])
            if combined < best - gains.max():
                z, best = z + move, combined
            else:
                k = int(np.argmax(gains))
                z, best = trials[k], float(values[k])
        log(f"silhouette refinement: step {step:.3f}, cost {best:.4f}")
    return z


def scaled_proxy(subject, proxy, proportions):
    """(body, proxy) of `subject` with the tracker's proxy skin, scaled to `proportions`."""
    body = scaled_body(_proxy_body(subject, proxy), proportions)
    return body, dataclasses.replace(proxy, vertices=body.vertices)


@dataclasses.dataclass
class CalibrationTargets:
    """What the masks' refinement and the check against the rig compare a body with, per calibration frame."""
    masks: list       # per frame one bool mask per camera, at the finest resolution the tracker computes
    cameras: list     # the capture's cameras at that resolution
    keypoints: list   # per frame KeypointTargets at that resolution
    mask_scale: float  # that resolution over the capture's

    def resolution(self, tracker):
        """The masks' scale over the tracker's energy scale (refit_poses' `resolution`)."""
        return self.mask_scale / tracker.scale


def calibration_targets(tracker, subject, frames, poses, landmarks, visibility):
    """CalibrationTargets of `frames`: the tracker's person masks with the learned model's crops around `poses`
    (absolute, of `subject`), and the saved landmarks (F,C,33,2) / visibility (F,C,33) of those frames."""
    from ..evidence.keypoints import rig_keypoints
    from .landmark_fit import targets_from_landmarks

    masks, cameras = calibration_masks(tracker, frames, poses)
    mask_scale = cameras[0].width / tracker.capture.cameras[0].width
    rig = rig_keypoints(subject, tracker.settings.landmarks)
    keypoints = [targets_from_landmarks(uv, vis, rig).scaled(mask_scale) for uv, vis in zip(landmarks, visibility)]
    return CalibrationTargets(masks, cameras, keypoints, mask_scale)


def refine_fit(fit, subject, tracker, landmarks, visibility, segments=SILHOUETTE_SEGMENTS, rounds=ROUNDS,
               log=None, targets=None):
    """The landmark fit `fit` (core/actor/landmark_fit.fit_proportions) refined against the person masks the
    tracker computes for its frames. landmarks (F,C,33,2) / visibility (F,C,33): the saved landmarks of
    fit.frames, in that order; targets: their calibration_targets around fit.poses when already made.
    Returns a ProportionsFit (lengths recomputed, .silhouettes filled in)."""
    t = targets or calibration_targets(tracker, subject, fit.frames, fit.poses, landmarks, visibility)
    mask_scale = t.mask_scale
    refinement = refine_proportions(subject, tracker.proxy, t.cameras, t.masks, fit.poses, fit.proportions,
                                    backend=tracker.settings.backend, log=log, rounds=rounds, keypoints=t.keypoints,
                                    resolution=t.resolution(tracker), segments=segments,
                                    landmarks=tracker.settings.landmarks)
    return dataclasses.replace(
        fit, proportions=refinement.proportions,
        lengths=segment_lengths(scaled_body(subject, refinement.proportions)),
        silhouettes={"segments": list(segments), "landmark_factors": fit.proportions.factors,
                     "landmark_lengths_m": fit.lengths, "mask_mismatch": {"landmark_fit": refinement.cost_before,
                                                                          "refined": refinement.cost_after},
                     "mask_scale": mask_scale, "evaluations": refinement.evaluations,
                     "kept_at_landmark_fit": refinement.kept})


def calibration_masks(tracker, frames, poses):
    """The person masks the tracker uses (learned, or background subtraction where it found none), per frame
    and camera, at its refinement resolution (the finest it computes), with the learned model's crops placed
    around `poses` (absolute, of `tracker.body`). Returns (masks, cameras at their resolution)."""
    masks = []
    for frame, pose in zip(frames, np.asarray(poses, float)):
        feats = tracker.features(int(frame), guide_poses=np.asarray(pose)[None])
        fine = tracker.fine_silhouettes
        masks.append([np.asarray(m, bool) for m in (fine if fine is not None else [f.silhouette for f in feats])])
    scale = tracker.refine_scale if tracker.fine_silhouettes is not None else tracker.scale
    return masks, [c.scaled(scale) for c in tracker.capture.cameras]
