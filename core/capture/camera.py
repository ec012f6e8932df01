"""The OpenCV pinhole camera (K, distortion, R, t) and its Blender equivalent.

Conventions (OpenCV): a world point X maps to camera coordinates Xc = R X + t (world -> camera);
camera axes +x right, +y down, +z forward; pixel (0, 0) is the *centre* of the top-left pixel.
Distortion coefficients follow OpenCV's order k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4]]].

Blender conversion formulas: docs blender-and-calibration.md sections 5.4 / 5.5, which mirror
Blender's BKE_camera_params_compute_viewplane / BKE_camera_sensor_fit / BKE_camera_sensor_size.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

_DIST_LENGTHS = (0, 4, 5, 8, 12)
_SENSOR_FITS = ("AUTO", "HORIZONTAL", "VERTICAL")
# OpenCV camera axes -> Blender camera axes (Blender cameras look down local -Z with +Y up).
_FLIP_YZ = np.diag([1.0, -1.0, -1.0])


class CameraError(InputError):
    """A camera's parameters are unusable (wrong shape, not a rotation, non-positive focal...)."""


def rodrigues_to_matrix(rvec) -> np.ndarray:
    """Rotation vector (axis * angle, radians) -> 3x3 rotation matrix (same as cv2.Rodrigues)."""
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(r))
    if theta < 1e-12:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)


def matrix_to_rodrigues(R) -> np.ndarray:
    """3x3 rotation matrix -> rotation vector (uses OpenCV, robust near 180 degrees)."""
    import cv2

    rvec, _ = cv2.Rodrigues(np.asarray(R, dtype=np.float64).reshape(3, 3))
    return rvec.reshape(3)


def rotation_problem(R, tol: float = 1e-6) -> str | None:
    """Why R is not a proper rotation matrix, or None if it is one (within tol)."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        return f"has shape {R.shape}; expected 3x3"
    if not np.all(np.isfinite(R)):
        return "contains NaN or infinite values"
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > tol:
        return f"is not orthonormal (max |R R^T - I| = {err:.2e})"
    if np.linalg.det(R) < 0:
        return "is a reflection (determinant -1), not a rotation"
    return None


@dataclass
class Camera:
    name: str
    K: np.ndarray  # 3x3 intrinsics
    dist: np.ndarray  # (0,), (4,), (5,), (8,) or (12,) OpenCV order
    R: np.ndarray  # 3x3 world -> camera rotation
    t: np.ndarray  # (3,) world -> camera translation, metres
    width: int
    height: int

    def __post_init__(self):
        self.K = np.array(self.K, dtype=np.float64)
        self.dist = np.array(self.dist, dtype=np.float64).reshape(-1)
        self.R = np.array(self.R, dtype=np.float64)
        self.t = np.array(self.t, dtype=np.float64).reshape(-1)
        who = f"camera '{self.name}'"
        if self.K.shape != (3, 3):
            raise CameraError(f"{who}: K has shape {self.K.shape}; expected 3x3")
        if not np.all(np.isfinite(self.K)):
            raise CameraError(f"{who}: K contains NaN or infinite values")
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise CameraError(f"{who}: focal lengths must be positive (fx={self.K[0, 0]}, fy={self.K[1, 1]})")
        if np.any(np.abs(self.K[2] - [0.0, 0.0, 1.0]) > 1e-9) or abs(self.K[1, 0]) > 1e-9:
            raise CameraError(f"{who}: K must look like [[fx, s, cx], [0, fy, cy], [0, 0, 1]]; got {self.K.tolist()}")
        if self.dist.size not in _DIST_LENGTHS:
            raise CameraError(
                f"{who}: {self.dist.size} distortion coefficients; expected one of {_DIST_LENGTHS} "
                "(OpenCV order k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4]]])")
        if not np.all(np.isfinite(self.dist)):
            raise CameraError(f"{who}: distortion contains NaN or infinite values")
        problem = rotation_problem(self.R)
        if problem:
            raise CameraError(f"{who}: rotation {problem}")
        if self.t.shape != (3,) or not np.all(np.isfinite(self.t)):
            raise CameraError(f"{who}: translation must be 3 finite numbers; got {self.t.tolist()}")
        if int(self.width) != self.width or int(self.height) != self.height or self.width <= 0 or self.height <= 0:
            raise CameraError(f"{who}: image size must be positive integers; got {self.width} x {self.height}")
        self.width, self.height = int(self.width), int(self.height)

    # ---- derived quantities -------------------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, C = -R^T t."""
        return -self.R.T @ self.t

    @property
    def rvec(self) -> np.ndarray:
        return matrix_to_rodrigues(self.R)

    @property
    def projection_matrix(self) -> np.ndarray:
        """3x4 P = K [R | t] (no distortion)."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    # ---- projection ---------------------------------------------------------------------------
    def to_camera(self, points) -> np.ndarray:
        """World points (..., 3) -> camera coordinates (..., 3)."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.R.T + self.t

    def _distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's lens model (as in cv2.projectPoints) on normalised coordinates x = X/Z, y = Y/Z."""
        d = np.zeros(12)
        d[: self.dist.size] = self.dist
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
        r2 = x * x + y * y
        r4 = r2 * r2
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        if k4 or k5 or k6:
            radial = radial / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xy2 = 2 * x * y
        xd = x * radial + p1 * xy2 + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + p2 * xy2
        if s1 or s2 or s3 or s4:
            xd += s1 * r2 + s2 * r4
            yd += s3 * r2 + s4 * r4
        return xd, yd

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist))

    def distort_normalized(self, xy) -> np.ndarray:
        """Apply the lens model to normalised coordinates (x/z, y/z), (..., 2) -> (..., 2)."""
        xy = np.asarray(xy, dtype=np.float64)
        if not self.has_distortion:
            return xy
        xd, yd = self._distort(xy[..., 0], xy[..., 1])
        return np.stack([xd, yd], axis=-1)

    def project_with_depth(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points (..., 3) -> pixels (..., 2) and depth (...,) = camera z.

        Points at or behind the camera (depth <= 0) get meaningless pixels: mask them with depth.
        Works on one flat (N, 3) block (one matmul, then column operations) to avoid batched matmuls.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3); got {p.shape}")
        lead = p.shape[:-1]
        pc = p.reshape(-1, 3) @ self.R.T
        pc += self.t
        z = pc[:, 2].copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_z = 1.0 / z
        x = pc[:, 0] * inv_z
        y = pc[:, 1] * inv_z
        if self.has_distortion:
            x, y = self._distort(x, y)
        K = self.K
        uv = np.empty((x.shape[0], 2))
        np.multiply(x, K[0, 0], out=uv[:, 0])
        if K[0, 1]:
            uv[:, 0] += K[0, 1] * y
        uv[:, 0] += K[0, 2]
        np.multiply(y, K[1, 1], out=uv[:, 1])
        uv[:, 1] += K[1, 2]
        return uv.reshape(lead + (2,)), z.reshape(lead)

    def project(self, points) -> np.ndarray:
        """World points (..., 3) -> pixels (..., 2), with distortion; any leading batch shape."""
        return self.project_with_depth(points)[0]

    def undistort_points(self, uv) -> np.ndarray:
        """Distorted pixels (..., 2) -> the pixels an ideal (distortion-free) camera with the same K sees."""
        import cv2

        uv = np.asarray(uv, dtype=np.float64)
        if not self.has_distortion:
            return uv.copy()
        flat = uv.reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        out = cv2.undistortPointsIter(flat, self.K, self.dist, None, self.K, criteria)
        return out.reshape(uv.shape)

    # ---- variants -----------------------------------------------------------------------------
    def scaled(self, factor: float) -> "Camera":
        """The same camera for the image resized by `factor` (e.g. 0.5 for half resolution).

        The new size is rounded to whole pixels and K uses the actual per-axis ratio new/old, so
        it matches cv2.resize(image, (new_w, new_h)). Pixel centres sit at half-pixel offsets from
        the image edge, so c' = (c + 0.5) * s - 0.5 (not c * s).
        """
        if not np.isfinite(factor) or factor <= 0:
            raise CameraError(f"camera '{self.name}': scale factor must be positive; got {factor}")
        new_w = max(1, int(round(self.width * factor)))
        new_h = max(1, int(round(self.height * factor)))
        sx, sy = new_w / self.width, new_h / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 1] *= sx
        K[1, 1] *= sy
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return Camera(self.name, K, self.dist.copy(), self.R.copy(), self.t.copy(), new_w, new_h)

    def without_distortion(self) -> "Camera":
        return Camera(self.name, self.K.copy(), np.zeros(0), self.R.copy(), self.t.copy(), self.width, self.height)


# ---- Blender ----------------------------------------------------------------------------------
@dataclass
class BlenderCameraParams:
    """Everything a Blender camera object and the scene's render settings need."""

    matrix_world: np.ndarray  # 4x4, object scale 1
    lens: float  # mm
    sensor_width: float  # mm
    sensor_height: float  # mm
    sensor_fit: str  # 'AUTO' | 'HORIZONTAL' | 'VERTICAL'
    shift_x: float
    shift_y: float
    resolution_x: int
    resolution_y: int
    pixel_aspect_x: float = 1.0
    pixel_aspect_y: float = 1.0
    name: str = field(default="")


def _viewfac(sensor_fit: str, width: int, height: int, aspx: float, aspy: float) -> tuple[float, float]:
    """Blender's (viewfac, ycor): the pixel extent the sensor spans, and the pixel aspect ratio."""
    ycor = aspy / aspx
    fit = sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if aspx * width >= aspy * height else "VERTICAL"
    viewfac = float(width) if fit == "HORIZONTAL" else ycor * height
    return viewfac, ycor


def _check_fit(sensor_fit: str) -> str:
    fit = str(sensor_fit).upper()
    if fit not in _SENSOR_FITS:
        raise CameraError(f"sensor_fit {sensor_fit!r} is not one of {_SENSOR_FITS}")
    return fit


def camera_to_blender(cam: Camera, sensor_width: float = 36.0, sensor_fit: str = "AUTO") -> BlenderCameraParams:
    """OpenCV camera -> Blender camera + render settings (distortion cannot be represented; dropped).

    Blender has no skew, so K[0,1] must be zero. fx != fy becomes a non-square pixel aspect.
    """
    fit = _check_fit(sensor_fit)
    if sensor_width <= 0:
        raise CameraError(f"sensor_width must be positive; got {sensor_width}")
    K = cam.K
    if abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise CameraError(f"camera '{cam.name}': Blender cameras cannot represent skew (K[0,1]={K[0, 1]})")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    W, H = cam.width, cam.height
    if fx >= fy:
        aspx, aspy = 1.0, fx / fy
    else:
        aspx, aspy = fy / fx, 1.0
    viewfac, ycor = _viewfac(fit, W, H, aspx, aspy)
    # A sensor with the image's aspect, so the camera frame looks right in the viewport.
    sensor_height = sensor_width * (H * aspy) / (W * aspx)
    sensor = sensor_height if fit == "VERTICAL" else sensor_width
    lens = fx * sensor / viewfac
    u0, v0 = cx + 0.5, cy + 0.5  # pixel-centre origin -> image-edge origin
    shift_x = (W / 2 - u0) / viewfac
    shift_y = (v0 - H / 2) * ycor / viewfac
    M = np.eye(4)
    M[:3, :3] = cam.R.T @ _FLIP_YZ
    M[:3, 3] = cam.center
    return BlenderCameraParams(M, float(lens), float(sensor_width), float(sensor_height), fit, float(shift_x),
                               float(shift_y), int(W), int(H), float(aspx), float(aspy), cam.name)


def camera_from_blender(params: BlenderCameraParams, name: str = "") -> Camera:
    """Blender camera + render settings -> OpenCV camera (zero distortion). Inverse of camera_to_blender."""
    fit = _check_fit(params.sensor_fit)
    M = np.asarray(params.matrix_world, dtype=np.float64)
    if M.shape != (4, 4):
        raise CameraError(f"matrix_world has shape {M.shape}; expected 4x4")
    # Drop any object scale (e.g. a display scale) so the 3x3 block is a pure rotation.
    rot = M[:3, :3] / np.linalg.norm(M[:3, :3], axis=0, keepdims=True)
    R = _FLIP_YZ @ rot.T
    t = -R @ M[:3, 3]
    W, H = int(params.resolution_x), int(params.resolution_y)
    viewfac, ycor = _viewfac(fit, W, H, float(params.pixel_aspect_x), float(params.pixel_aspect_y))
    sensor = params.sensor_height if fit == "VERTICAL" else params.sensor_width
    fx = params.lens * viewfac / sensor
    fy = fx / ycor
    cx = W / 2 - params.shift_x * viewfac - 0.5
    cy = H / 2 + params.shift_y * viewfac / ycor - 0.5
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return Camera(name or params.name, K, np.zeros(0), R, t, W, H)
