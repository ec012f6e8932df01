"""ICP with twists: the local single-hypothesis optimiser of the paper's eq. (8) (algorithms.md 6).

    V(x) = sum_v sum_i || pi_v(X_i(x)) - p_{v,i} ||^2

X_i are the posed proxy's visible silhouette-rim vertices (core/render/rim.py) and p_{v,i} their
closest points on the observed silhouette contour of view v. Each outer iteration re-finds the
correspondences, then takes Levenberg-Marquardt steps on them (Huber-weighted, IRLS) with the
analytic Jacobian:

* joint angle j (a twist with world axis w'_j through the joint centre q'_j in the current pose):
  dX/dtheta_j = sum_s w_s share (w'_j x (X_s - q'_j)), over the bones s the joint moves;
* root translation: dX/dt = I; root rotation: a left increment d in world axes, dX/dd = -[X - c]x,
  c = the root joint. The update r <- log(exp([d]x) exp([r]x)) keeps that derivative exact;
* chain rule through the camera: d(pixel)/dX = K_2x2 . d(distortion) . d(x/z, y/z)/dX_cam . R.

The data term is the *mean* Huber loss per correspondence (px^2), so the anatomical prior
(lambda_anat V_anat, A9) keeps the same weight whatever the number of rim points; the prior enters
the normal equations with its gradient and a finite-difference Hessian. residual="line" uses only
the component of u - p along the contour normal (point-to-line ICP): same fixed point, but rim
points may slide along the outline, which converges much faster (tests/test_icp.py measures both). ICP uses no
black-box energy evaluations in its search; the base class scores the final estimate once.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..capture.camera import Camera
from ..render.rim import MeshEdges, rim_vertices
from ..body.rotations import axis_angle_matrix, matrix_to_rotvec, rotvec_to_matrix, skew
from .base import CountingEnergy, Optimizer, OptimizerInputError, PoseSpace

MIN_CORRESPONDENCES = 6  # below this an iteration cannot constrain a pose: stop instead of guessing
LM_TRIES = 6  # damping increases per outer iteration before giving up on a step


class IcpProblemError(OptimizerInputError):
    """The per-frame data handed to ICP (cameras, silhouettes, body) is inconsistent."""


def _identity(poses):
    return np.array(poses, dtype=np.float64, copy=True)


@dataclass
class IcpProblem:
    """One frame's observation for ICP, at the energy resolution.

    to_absolute maps the optimiser's (relative) poses to absolute ones; it must express the root
    rotation as exp([r]x) @ anchor (the Tracker's convention), so a left increment of the relative
    rotation is a left increment of the absolute one. prior: an object with energy(poses) -> (P,)
    and gradient(poses) -> (P, D) on absolute poses (the anatomical prior), or None.
    """

    body: object
    proxy: object
    cameras: list
    silhouettes: list
    to_absolute: Callable[[np.ndarray], np.ndarray] = _identity
    prior: object | None = None
    # Learned landmarks (core/evidence/keypoints.KeypointTargets at this problem's resolution) and the rig points
    # they stand for: residuals beside the rim correspondences, so the local fit keeps what they show
    # (a hand in front of the torso has no rim).
    keypoints: object | None = None
    rig_points: object | None = None
    # Per view, where other tracked actors' bodies are (bool, at this problem's resolution), or None: contour
    # there may be theirs and this actor's rim there may be hidden, so neither makes a correspondence.
    others: list | None = None

    def __post_init__(self):
        if len(self.cameras) == 0:
            raise IcpProblemError("ICP needs at least one camera with its silhouette")
        if len(self.cameras) != len(self.silhouettes):
            raise IcpProblemError(f"{len(self.cameras)} cameras but {len(self.silhouettes)} silhouettes: give "
                                  f"one silhouette per camera, in the same order")
        sils = []
        for cam, sil in zip(self.cameras, self.silhouettes):
            if not isinstance(cam, Camera):
                raise IcpProblemError(f"cameras must be core.capture.camera.Camera objects, got {type(cam).__name__}")
            sil = np.asarray(sil)
            if sil.shape != (cam.height, cam.width):
                raise IcpProblemError(f"silhouette of camera {cam.name!r} has shape {sil.shape} but the camera is "
                                      f"{cam.width}x{cam.height}: scale the camera (Camera.scaled) to the "
                                      f"silhouette's resolution")
            sils.append(sil > 0)
        self.silhouettes = sils
        if self.others is not None:
            if len(self.others) != len(sils) or any(np.shape(o) != s.shape for o, s in zip(self.others, sils)):
                raise IcpProblemError("give the other actors' masks one per camera, each the silhouette's size")
            self.others = [np.asarray(o, dtype=bool) for o in self.others]
        if self.to_absolute is None:
            self.to_absolute = _identity
        if self.prior is not None and not (hasattr(self.prior, "energy") and hasattr(self.prior, "gradient")):
            raise IcpProblemError("prior must provide energy(poses) and gradient(poses) (an AnatomicalPrior)")


# ---------------------------------------------------------------- the observed side

@dataclass
class ContourField:
    """The observed contour of one view: its points (half a pixel outside the contour pixels) and outward
    normals, with a k-d tree for the nearest one to any pixel.

    Only the pixels ICP asks about are looked up (a few hundred rim points per view), so nothing is
    computed for the whole image: the smoothing that gives the normals runs on the silhouette's box.
    """

    points: np.ndarray  # (N,2) x, y of the contour pixels
    normals: np.ndarray  # (N,2) outward unit normal at each
    tree: object | None
    n_contour: int
    excluded: np.ndarray | None = None  # (H,W) bool: pixels another actor covers (no rim point there counts)

    @classmethod
    def from_silhouette(cls, silhouette, smoothing: float = 1.0, excluded=None) -> "ContourField":
        sil = np.asarray(silhouette, dtype=bool)
        rows, cols = np.nonzero(np.any(sil, axis=1)), np.nonzero(np.any(sil, axis=0))
        if len(rows[0]) == 0:
            return cls(np.zeros((0, 2)), np.zeros((0, 2)), None, 0, excluded)
        # The box with a ring wide enough that the Gaussian (radius 4 sigma) and the gradient see only
        # zeros beyond it: the result equals the full image's.
        H, W = sil.shape
        ring = int(4.0 * smoothing + 0.5) + 2
        y0, y1 = max(rows[0][0] - ring, 0), min(rows[0][-1] + ring + 1, H)
        x0, x1 = max(cols[0][0] - ring, 0), min(cols[0][-1] + ring + 1, W)
        box = sil[y0:y1, x0:x1]
        # Contour: silhouette pixels with a background 4-neighbour (the image border does not count).
        contour = box & ~ndimage.binary_erosion(box, border_value=1)
        cy, cx = np.nonzero(contour)
        # Outward normal = minus the gradient of the smoothed mask.
        smooth = ndimage.gaussian_filter(box.astype(np.float64), smoothing)
        gy, gx = np.gradient(smooth)
        g = np.stack([-gx[cy, cx], -gy[cy, cx]], axis=-1)
        length = np.linalg.norm(g, axis=-1, keepdims=True)
        g = np.divide(g, length, out=np.zeros_like(g), where=length > 1e-12)
        points = np.stack([cx + x0, cy + y0], axis=-1).astype(np.float64)
        if excluded is not None:  # the others' outline, or this actor's against theirs: not this actor's contour
            keep = ~excluded[cy + y0, cx + x0]
            points, g = points[keep], g[keep]
            if len(points) == 0:
                return cls(np.zeros((0, 2)), np.zeros((0, 2)), None, 0, excluded)
        return cls(points, g, cKDTree(points), len(points), excluded)

    def excludes(self, rows, cols):
        """(n,) bool: which pixels lie where another actor is (out of the image: no)."""
        if self.excluded is None:
            return np.zeros(len(rows), dtype=bool)
        h, w = self.excluded.shape
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        out = np.zeros(len(rows), dtype=bool)
        out[inside] = self.excluded[rows[inside], cols[inside]]
        return out

    def lookup(self, rows, cols):
        """Nearest contour point (x, y; the true outline runs about half a pixel outside the contour
        pixel's centre) and its outward normal for each pixel (rows[i], cols[i]): (n,2), (n,2)."""
        _, index = self.tree.query(np.stack([cols, rows], axis=-1).astype(np.float64))
        normal = self.normals[index]
        return self.points[index] + 0.5 * normal, normal


# ---------------------------------------------------------------- derivatives

def descendant_matrix(skeleton) -> np.ndarray:
    """(B,B) float: D[a, s] = 1 when bone a is s or one of its ancestors (a moves s)."""
    B = skeleton.n_bones
    D = np.zeros((B, B))
    for s in range(B):
        a = s
        while a >= 0:
            D[a, s] = 1.0
            a = int(skeleton.parents[a])
    return D


def vertex_jacobian(body, pose_abs, rest_vertices, weights, descendants=None) -> np.ndarray:
    """vertex_jacobian_reference, compiled (core/optimizers/jacobian_fast.py) when numba is there."""
    fast = _fast_jacobian()
    if fast is None:
        return vertex_jacobian_reference(body, pose_abs, rest_vertices, weights, descendants)
    return fast.vertex_jacobian(body, pose_abs, rest_vertices, weights)


@functools.cache
def _fast_jacobian():
    try:
        from . import jacobian_fast as fast_jacobian
    except ImportError:
        return None
    return fast_jacobian


def vertex_jacobian_reference(body, pose_abs, rest_vertices, weights, descendants=None) -> np.ndarray:
    """(N,3,D) derivative of the skinned world vertices at one absolute pose (twists, module doc).

    rest_vertices (N,3) armature space and weights (N,B) as in Body.deform (unweighted vertices have
    zero weights and get zero rows: they do not move). Root rotation columns are w.r.t. a left
    increment in world axes; every other column w.r.t. the DOF itself.
    """
    sk = body.skeleton
    x = np.asarray(pose_abs, dtype=np.float64).reshape(-1)
    D = descendant_matrix(sk) if descendants is None else descendants
    world = body.pose_matrices(x[None])[0]  # (B,4,4)
    skin = world @ sk.inv_rest
    Xs = np.tensordot(rest_vertices, skin[:, :3, :3], axes=([1], [2])) + skin[:, :3, 3]  # (N,B,3) per bone
    S = np.matmul(D, weights[:, :, None] * Xs)  # (N,B,3): weighted sum over the bones each bone moves
    Wd = weights @ D.T  # (N,B) weight each bone moves
    J = np.zeros((len(rest_vertices), 3, body.n_dof))
    r = body.root_bone
    for b in range(sk.n_bones):
        if b == r or not body.bone_dofs[b]:
            continue
        p = int(sk.parents[b])
        G = (world[p] if p >= 0 else sk.armature_matrix) @ sk.rest_relative[b]  # bone frame before its basis
        R = G[:3, :3] / np.cbrt(np.linalg.det(G[:3, :3]))  # drop a uniform object scale
        lever = S[:, b] - Wd[:, b, None] * G[:3, 3]  # sum_s w_s (X_s - q')
        acc = np.eye(3)
        for i, axis, share in body.bone_dofs[b]:
            w = R @ (acc @ axis)
            # w x lever for every row, as one small matmul (np.cross's overhead was most of the local fit's)
            J[:, :, i] += lever @ (share * skew(w / math.sqrt(float(w @ w)))).T
            acc = acc @ axis_angle_matrix(axis, x[i] * share)
    J[:, :, body.translation_dofs] = Wd[:, r, None, None] * np.eye(3)
    lever = S[:, r] - Wd[:, r, None] * world[r, :3, 3]
    for k, i in enumerate(body.root_rotation_dofs):
        J[:, :, i] = lever @ skew(np.eye(3)[k]).T
    return J


def projection_jacobian(camera: Camera, points, step: float = 1e-7) -> np.ndarray:
    """(N,2,3) derivative of camera.project at world points (N,3); lens distortion included
    (its 2x2 derivative in normalised coordinates by central differences)."""
    p = np.asarray(points, dtype=np.float64)
    pc = p @ camera.R.T + camera.t
    z = pc[:, 2]
    xn, yn = pc[:, 0] / z, pc[:, 1] / z
    dn = np.zeros((len(p), 2, 3))  # d(x/z, y/z)/d(camera coordinates)
    dn[:, 0, 0] = 1.0 / z
    dn[:, 0, 2] = -xn / z
    dn[:, 1, 1] = 1.0 / z
    dn[:, 1, 2] = -yn / z
    if camera.has_distortion:
        xy = np.stack([xn, yn], axis=1)
        e = np.array([[step, 0.0], [-step, 0.0], [0.0, step], [0.0, -step]])
        moved = camera.distort_normalized(xy[None] + e[:, None]).reshape(4, len(p), 2)  # one call for all four
        dd = np.stack([moved[0] - moved[1], moved[2] - moved[3]], axis=-1) / (2 * step)  # (N, 2, 2)
        dn = dd @ dn
    K2 = camera.K[:2, :2]
    return K2 @ dn @ camera.R


def apply_increment(x, delta, root_rotation_dofs) -> np.ndarray:
    """x (+) delta: additive for every DOF except the root rotation, which composes on the left."""
    out = np.asarray(x, dtype=np.float64) + delta
    rd = np.asarray(root_rotation_dofs)
    if rd.size:
        out[rd] = matrix_to_rotvec(rotvec_to_matrix(delta[rd]) @ rotvec_to_matrix(np.asarray(x)[rd]))
    return out


# ---------------------------------------------------------------- correspondences

@dataclass
class Correspondences:
    view: np.ndarray  # (N,) view index
    vertex: np.ndarray  # (N,) proxy vertex id
    target: np.ndarray  # (N,2) closest contour point (pixels)
    normal: np.ndarray | None = None  # (N,2) outward contour normal there (for point-to-line residuals)
    rim_count: int = 0  # rim vertices found before the distance/normal tests

    def __len__(self):
        return len(self.vertex)


def find_correspondences(vertices, proxy_faces, edges, cameras, fields, d_max, cos_min) -> Correspondences:
    views, verts, targets, normals, n_rim = [], [], [], [], 0
    for v, (cam, fld) in enumerate(zip(cameras, fields)):
        if fld.n_contour == 0:
            continue
        rim = rim_vertices(vertices, proxy_faces, cam, edges)
        n_rim += len(rim)
        if len(rim) == 0:
            continue
        col = np.rint(rim.uv[:, 0]).astype(np.int64)
        row = np.rint(rim.uv[:, 1]).astype(np.int64)
        p, n = fld.lookup(row, col)
        ok = np.linalg.norm(rim.uv - p, axis=1) <= d_max
        ok &= np.einsum("ni,ni->n", rim.normal, n) >= cos_min
        ok &= ~fld.excludes(row, col)
        views.append(np.full(int(ok.sum()), v))
        verts.append(rim.vertex[ok])
        targets.append(p[ok])
        normals.append(n[ok])
    if not verts:
        return Correspondences(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 2)), n_rim)
    return Correspondences(np.concatenate(views), np.concatenate(verts), np.concatenate(targets),
                           np.concatenate(normals), n_rim)


def huber_loss(e, delta):
    return np.where(e <= delta, 0.5 * e * e, delta * (e - 0.5 * delta))


# ---------------------------------------------------------------- the solver

@dataclass
class IcpSettings:
    iterations: int = 10
    d_max: float = 20.0  # px at the energy resolution; halved every `shrink_every` iterations
    d_min: float = 5.0
    shrink_every: int = 3
    normal_angle: float = 60.0  # degrees
    huber: float = 3.0  # px
    prior_weight: float = 2.0
    keypoint_weight: float = 0.2  # of the mean Huber keypoint loss (px^2), beside the rim term's
    keypoint_huber: float = 4.0  # px
    residual: str = "point"  # "point": u - p (eq. 8); "line": its component along the contour normal
    step_tol: float = 1e-4  # stop when every |delta| / scale falls below this
    cost_tol: float = 1e-4  # ... or the relative cost decrease does

    def at_resolution(self, factor: float) -> "IcpSettings":
        """The same fit on images `factor` x as fine: the pixel distances grow with them, and the prior grows
        as the (mean, squared) image residuals do, so the balance of the terms holds."""
        return dataclasses.replace(self, d_max=self.d_max * factor, d_min=self.d_min * factor,
                                   huber=self.huber * factor, keypoint_huber=self.keypoint_huber * factor,
                                   prior_weight=self.prior_weight * factor ** 2)

    def with_iterations(self, n: int) -> "IcpSettings":
        """The same schedule over `n` iterations: the correspondence distance halves as often, in proportion."""
        n = int(n)
        return dataclasses.replace(self, iterations=n,
                                   shrink_every=max(1, round(self.shrink_every * n / self.iterations)))

    def d_max_at(self, it: int) -> float:
        return max(self.d_min, self.d_max * 0.5 ** (it // self.shrink_every))


@dataclass
class IcpFitResult:
    pose: np.ndarray  # relative pose (the optimiser's coordinates)
    info: dict = field(default_factory=dict)


class IcpSolver:
    """Runs ICP on one IcpProblem; holds the per-frame contour fields and per-mesh edge table."""

    def __init__(self, problem: IcpProblem, space: PoseSpace, settings: IcpSettings):
        self.problem, self.space, self.settings = problem, space, settings
        body, proxy = problem.body, problem.proxy
        if body.n_dof != space.dim:
            raise IcpProblemError(f"the body has {body.n_dof} DOF but the pose space {space.dim}: build both "
                                  f"from the same body")
        self.edges = MeshEdges.from_faces(proxy.faces)
        others = problem.others or [None] * len(problem.silhouettes)
        self.fields = [ContourField.from_silhouette(s, excluded=o) for s, o in zip(problem.silhouettes, others)]
        self.descendants = descendant_matrix(body.skeleton)
        self.weights = np.where(proxy.unweighted[:, None], 0.0, proxy.weights)

    def _absolute(self, x):
        return np.asarray(self.problem.to_absolute(x[None]), dtype=np.float64).reshape(-1)

    def _vertices(self, x_abs):
        return self.problem.proxy.deform(self.problem.body, x_abs[None])[0]

    def _prior(self, x_abs, derivatives=False):
        """lambda V_prior at x_abs; with derivatives also its gradient and a PSD Hessian.

        The Hessian comes from central differences of the prior's gradient (one batched call),
        projected onto the positive semidefinite cone: without it a stiff prior makes LM crawl,
        because the data term's curvature alone badly predicts the prior's change.
        """
        prior, lam, body = self.problem.prior, self.settings.prior_weight, self.problem.body
        d = x_abs.shape[0]
        if prior is None or lam == 0:
            return (0.0, np.zeros(d), np.zeros((d, d))) if derivatives else 0.0
        e = lam * float(np.asarray(prior.energy(x_abs[None])).reshape(-1)[0])
        if not derivatives:
            return e
        # The prior ignores the root; its rotation also lives in another chart (left increments here).
        free = np.setdiff1d(np.arange(d), body.root_rotation_dofs)
        h = 1e-3 * self.space.scale[free]
        probes = np.repeat(x_abs[None], 2 * free.size + 1, axis=0)
        probes[1 + np.arange(free.size), free] += h
        probes[1 + free.size + np.arange(free.size), free] -= h
        grads = lam * np.asarray(prior.gradient(probes), dtype=np.float64).reshape(len(probes), d)
        g = grads[0].copy()
        g[body.root_rotation_dofs] = 0.0
        block = ((grads[1:1 + free.size] - grads[1 + free.size:]) / (2 * h[:, None]))[:, free]
        vals, vecs = np.linalg.eigh(0.5 * (block + block.T))
        H = np.zeros((d, d))
        H[np.ix_(free, free)] = (vecs * np.maximum(vals, 0.0)) @ vecs.T
        return e, g, H

    def _residuals(self, x_abs, corr: Correspondences, verts=None) -> np.ndarray:
        """(N,2) pixel of each correspondence's rim vertex minus its contour point."""
        verts = self._vertices(x_abs) if verts is None else verts
        r = np.empty((len(corr), 2))
        for v, cam in enumerate(self.problem.cameras):
            m = corr.view == v
            if m.any():
                r[m] = cam.project(verts[corr.vertex[m]]) - corr.target[m]
        return r

    # ---- keypoints ------------------------------------------------------------------------------
    def _keypoint_assignment(self, x_abs):
        """(C,K,2) landmark position each rig point is compared with (as the energy compares them: each
        view's left/right pairs as they fit the pose best, each landmark's best-fitting candidate) and its
        weight, or None without keypoints."""
        from ..evidence.keypoints import chosen_targets

        kp, rig = self.problem.keypoints, self.problem.rig_points
        if kp is None or rig is None or self.settings.keypoint_weight == 0:
            return None
        pts = rig.world(self.problem.body, x_abs[None])[0]
        projected = np.stack([cam.project(pts) for cam in self.problem.cameras])
        return chosen_targets(projected, kp, rig.swap)

    def _keypoint_residuals(self, x_abs, assignment):
        """(C,K,2) projected rig point minus its landmark."""
        target, _ = assignment
        pts = self.problem.rig_points.world(self.problem.body, x_abs[None])[0]
        return np.stack([cam.project(pts) for cam in self.problem.cameras]) - target

    def _keypoint_cost(self, x_abs, assignment):
        if assignment is None:
            return 0.0
        _, weight = assignment
        if weight.sum() <= 0:
            return 0.0
        e = np.linalg.norm(self._keypoint_residuals(x_abs, assignment), axis=-1)
        s = self.settings
        return s.keypoint_weight * float((weight * huber_loss(e, s.keypoint_huber)).sum() / weight.sum())

    def _keypoint_normal_equations(self, x_abs, assignment):
        """(H, g, cost) of the weighted mean Huber keypoint loss, Gauss-Newton with IRLS weights."""
        D = self.problem.body.n_dof
        if assignment is None or assignment[1].sum() <= 0:
            return np.zeros((D, D)), np.zeros(D), 0.0
        s, rig, body = self.settings, self.problem.rig_points, self.problem.body
        _, weight = assignment
        r = self._keypoint_residuals(x_abs, assignment)  # (C,K,2)
        e = np.linalg.norm(r, axis=-1)
        irls = weight * np.where(e <= s.keypoint_huber, 1.0, s.keypoint_huber / np.maximum(e, 1e-12))
        onehot = np.zeros((len(rig.bones), body.skeleton.n_bones))
        onehot[np.arange(len(rig.bones)), rig.bones] = 1.0
        J3 = vertex_jacobian(body, x_abs, rig.rest_points[:, :3], onehot, self.descendants)  # (K,3,D)
        pts = rig.world(body, x_abs[None])[0]
        H, g = np.zeros((D, D)), np.zeros(D)
        for c, cam in enumerate(self.problem.cameras):
            J = projection_jacobian(cam, pts) @ J3  # (K,2,D)
            w = np.repeat(irls[c], 2)
            Jf, rf = J.reshape(-1, D), r[c].reshape(-1)
            H += (Jf * w[:, None]).T @ Jf
            g += Jf.T @ (w * rf)
        norm = s.keypoint_weight / weight.sum()
        cost = s.keypoint_weight * float((weight * huber_loss(e, s.keypoint_huber)).sum() / weight.sum())
        return H * norm, g * norm, cost

    def _errors(self, r, corr):
        """Per-correspondence error (px) of the chosen residual."""
        if self.settings.residual == "line":
            return np.abs(np.einsum("ni,ni->n", r, corr.normal))
        return np.linalg.norm(r, axis=1)

    def _cost(self, x_abs, corr, assignment=None):
        e = self._errors(self._residuals(x_abs, corr), corr)
        return (float(huber_loss(e, self.settings.huber).mean()) + self._prior(x_abs)
                + self._keypoint_cost(x_abs, assignment))

    def residual_jacobian(self, x_abs, corr: Correspondences, verts=None) -> np.ndarray:
        """(N,2,D) derivative of every correspondence residual (pixel of the rim vertex)."""
        proxy = self.problem.proxy
        verts = self._vertices(x_abs) if verts is None else verts
        J3 = vertex_jacobian(self.problem.body, x_abs, proxy.vertices[corr.vertex], self.weights[corr.vertex],
                             self.descendants)
        J = np.empty((len(corr), 2, J3.shape[2]))
        for v, cam in enumerate(self.problem.cameras):
            m = corr.view == v
            if m.any():
                J[m] = projection_jacobian(cam, verts[corr.vertex[m]]) @ J3[m]
        return J

    def _normal_equations(self, x_abs, corr, r, e, verts):
        """Huber-IRLS Gauss-Newton system (H, g) of the mean data term plus the prior, and the cost."""
        s, n = self.settings, len(corr)
        w = np.where(e <= s.huber, 1.0, s.huber / np.maximum(e, 1e-12))
        J = self.residual_jacobian(x_abs, corr, verts)
        if s.residual == "line":
            J = np.einsum("ni,nid->nd", corr.normal, J)
            rv = np.einsum("ni,ni->n", r, corr.normal)
        else:
            J, rv, w = J.reshape(2 * n, -1), r.reshape(-1), np.repeat(w, 2)
        prior_e, prior_g, prior_H = self._prior(x_abs, derivatives=True)
        H = (J * w[:, None]).T @ J / n + prior_H
        g = J.T @ (w * rv) / n + prior_g
        return H, g, float(huber_loss(e, s.huber).mean()) + prior_e

    def fit(self, x_init) -> IcpFitResult:
        s, space = self.settings, self.space
        rd = self.problem.body.root_rotation_dofs
        cos_min = math.cos(math.radians(s.normal_angle))
        x = space.clamp(space.check_pose(x_init, "ICP initial pose"))
        mu = 1e-3
        history = {"correspondences": [], "rim_vertices": [], "mean_residual_px": [], "cost": [], "d_max": []}
        stop, it = "iterations", -1
        for it in range(s.iterations):
            x_abs = self._absolute(x)
            d_max = s.d_max_at(it)
            verts = self._vertices(x_abs)
            corr = find_correspondences(verts, self.problem.proxy.faces, self.edges, self.problem.cameras,
                                        self.fields, d_max, cos_min)
            history["correspondences"].append(len(corr))
            history["rim_vertices"].append(corr.rim_count)
            history["d_max"].append(d_max)
            if len(corr) < MIN_CORRESPONDENCES:
                stop = "too few correspondences"
                break
            r = self._residuals(x_abs, corr, verts)
            e = self._errors(r, corr)
            history["mean_residual_px"].append(float(np.linalg.norm(r, axis=1).mean()))
            H, g, cost0 = self._normal_equations(x_abs, corr, r, e, verts)
            assignment = self._keypoint_assignment(x_abs)
            H_kp, g_kp, cost_kp = self._keypoint_normal_equations(x_abs, assignment)
            H, g, cost0 = H + H_kp, g + g_kp, cost0 + cost_kp
            history["cost"].append(cost0)
            diag = np.diag(H).copy()
            diag = np.maximum(diag, 1e-9 * max(float(diag.mean()), 1e-300))  # unobserved DOF stay put
            accepted = False
            for _ in range(LM_TRIES):
                delta = np.linalg.solve(H + mu * np.diag(diag), -g)
                x_try = space.clamp(apply_increment(x, delta, rd))
                cost1 = self._cost(self._absolute(x_try), corr, assignment)
                if np.isfinite(cost1) and cost1 < cost0:
                    accepted = True
                    mu = max(mu / 10.0, 1e-7)
                    break
                mu *= 10.0
            if not accepted:
                stop = "no decrease"
                break
            x = x_try
            if (np.abs(delta) / space.scale).max() < s.step_tol or (cost0 - cost1) <= s.cost_tol * cost0:
                stop = "converged"
                break
        history.update(iterations=it + 1, stop=stop)
        return IcpFitResult(x, history)


# ---------------------------------------------------------------- the optimiser

class IterativeClosestPoint(Optimizer):
    """ICP tracker (algorithms.md 6). Call `set_frame_problem(IcpProblem)` before each track_frame.

    Initial value per frame: constant velocity 2 x_{t-1} - x_{t-2} when two estimates exist,
    else x_{t-1}, else the start pose (algorithms.md 4.5).
    """
    name = "icp"

    def __init__(self, space: PoseSpace, budget: int | None = None, seed: int = 0, *, iterations: int = 10,
                 d_max: float = 20.0, d_min: float = 5.0, normal_angle: float = 60.0, huber: float = 3.0,
                 prior_weight: float = 2.0, residual: str = "point", **params):
        super().__init__(space, budget, seed, **params)
        if int(iterations) != iterations or iterations < 1:
            raise OptimizerInputError(f"ICP iterations must be a positive integer, got {iterations!r}")
        if not (d_max > 0 and d_min > 0 and d_min <= d_max):
            raise OptimizerInputError(f"ICP needs 0 < d_min <= d_max (pixels), got d_min={d_min}, d_max={d_max}")
        if not 0 < normal_angle <= 180:
            raise OptimizerInputError(f"normal_angle must be in (0, 180] degrees, got {normal_angle}")
        if residual not in ("point", "line"):
            raise OptimizerInputError(f"ICP residual must be 'point' (u - p, eq. 8) or 'line' (along the contour "
                                      f"normal), got {residual!r}")
        if huber <= 0 or prior_weight < 0:
            raise OptimizerInputError("ICP needs huber > 0 (pixels) and prior_weight >= 0")
        self.settings = IcpSettings(iterations=int(iterations), d_max=float(d_max), d_min=float(d_min),
                                    normal_angle=float(normal_angle), huber=float(huber),
                                    prior_weight=float(prior_weight), residual=residual)
        self.problem: IcpProblem | None = None
        self._solver: IcpSolver | None = None

    def set_frame_problem(self, problem: IcpProblem) -> None:
        if not isinstance(problem, IcpProblem):
            raise IcpProblemError("set_frame_problem needs an IcpProblem (body, proxy, cameras, silhouettes, ...)")
        self.problem = problem
        self._solver = None  # contour fields are per frame: rebuilt lazily

    def predict(self, history) -> np.ndarray:
        if len(history) >= 2:
            return self.space.clamp(2.0 * history[-1] - history[-2])
        return history[-1].copy() if history else self.x0.copy()

    def _search(self, energy: CountingEnergy, history):
        if self.problem is None:
            raise IcpProblemError("ICP needs the frame's silhouettes: call set_frame_problem(IcpProblem(...)) "
                                  "before track_frame")
        t0 = time.perf_counter()
        if self._solver is None:
            self._solver = IcpSolver(self.problem, self.space, self.settings)
        x_init = self.predict(history)
        result = self._solver.fit(x_init)
        info = dict(result.info)
        info["seconds"] = time.perf_counter() - t0
        return result.pose, info
