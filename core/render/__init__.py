"""Rasterising the posed body into each view and reducing it to likelihood statistics.

reference.py: the plain NumPy definition (also renders images for overlays); fast.py: the numba kernel
that computes the same statistics without keeping images. `statistics(..., backend=)` picks one.
numba is optional: backend "auto" uses it when it imports, else warns once and uses NumPy.

"gpu" is the GLSL path (glsl.py's shaders, run by addon/gpu_likelihood.py on Blender's gpu module). It is
never chosen here by "auto" (that needs a probe in a subprocess: operators/backend_choice.py); it exists
in a process once the host has called `register_gpu`. It computes the silhouette and edge statistics; a
call that needs the template's chamfer transform or colour histograms, or whose targets mark other actors'
pixels (reference.OTHERS), runs on the CPU path instead.
"""
import warnings

import numpy as np

from .reference import (BOUNDARY, BOUNDARY_OFF, N_BINS, N_STATS, OTHERS, OVERLAP, SUM_DI, SUM_DT, SUM_EDGE_DT, TEMPLATE,
                        FrameTargets, RenderInputError, ab_to_bins, boundary_mask, chamfer_34, project_views, rasterize,
                        render_view)
from ..errors import InputError
from . import reference

BACKENDS = ("auto", "numpy", "fast", "gpu")
_warned = False
_gpu_measure = None  # set by register_gpu: (body, proxy, poses, cameras, faces, face_label, targets, cull) -> stats


class BackendUnavailableError(InputError, RuntimeError):
    """The backend asked for cannot run in this process; the message names the fix."""


def register_gpu(measure_poses):
    """Called by the GPU host (where bpy is allowed) to make backend "gpu" available."""
    global _gpu_measure
    _gpu_measure = measure_poses


def cpu_backend(backend="auto"):
    """The CPU path a backend uses for what it does not compute itself ("gpu" -> fast, else numpy)."""
    return resolve_backend("auto" if backend == "gpu" else backend)


def resolve_backend(backend="auto"):
    """"auto" | "numpy" | "fast" | "gpu" -> "numpy", "fast" or "gpu" (the fast path needs numba; "gpu" needs
    the GPU host registered, see register_gpu). "auto" here means the best CPU path."""
    global _warned
    if backend not in BACKENDS:
        raise ValueError(f"unknown render backend {backend!r}; choose one of {BACKENDS}")
    if backend == "numpy":
        return "numpy"
    if backend == "gpu":
        if _gpu_measure is None:
            raise BackendUnavailableError("the GPU likelihood is not set up in this process: run through "
                                          "`python -m markerless_mocap` or Blender (they install it), or choose "
                                          "backend 'fast'")
        return "gpu"
    try:
        from . import fast  # noqa: F401  (imports numba)
    except ImportError as exc:
        if backend == "fast":
            raise ImportError(f"the fast render backend needs numba ({exc}); install numba or use "
                              "backend='numpy'") from exc
        if not _warned:
            warnings.warn(f"numba is not available ({exc}); the likelihood uses the slow NumPy path", RuntimeWarning)
            _warned = True
        return "numpy"
    return "fast"


def statistics(uv, z, faces, face_label, targets, need_chamfer=True, n_parts=0, cull=0, backend="auto"):
    """(P,C,N_STATS) statistics and (P,C,S,2,K) part histograms for projected meshes (see reference.py)."""
    if cpu_backend(backend) == "fast":
        from . import fast
        return fast.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)
    return reference.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)


def measure_poses(body, proxy, poses, cameras, faces, face_label, targets, need_chamfer=True, n_parts=0, cull=0,
                  backend="auto"):
    """Poses (P,D) -> skinned proxy in every camera -> `statistics`. The GPU path skins in its vertex
    shader; the CPU paths (and the GPU backend for chamfer or colour statistics) skin here."""
    if resolve_backend(backend) == "gpu" and not need_chamfer and not n_parts and not targets.has_others:
        return _gpu_measure(body, proxy, poses, cameras, faces, face_label, targets, cull), \
            np.zeros((len(poses), len(cameras), 0, 2, N_BINS), dtype=np.int64)
    vertices = proxy.deform(body, poses)
    return measure_vertices(vertices, cameras, faces, face_label, targets, need_chamfer, n_parts, cull,
                            cpu_backend(backend))


def measure_vertices(vertices, cameras, faces, face_label, targets, need_chamfer=True, n_parts=0, cull=0,
                     backend="auto"):
    """Posed vertices (P,V,3) -> projection into every camera -> `statistics` (fast path: both in numba)."""
    if cpu_backend(backend) == "fast":
        from . import fast
        q, iz = fast.project_views(vertices, cameras)
        return fast.statistics_from_snapped(q, iz, faces, face_label, targets, need_chamfer, n_parts, cull)
    uv, z = project_views(vertices, cameras)
    return reference.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)


__all__ = ["statistics", "measure_vertices", "measure_poses", "resolve_backend", "register_gpu",
           "cpu_backend", "BackendUnavailableError", "FrameTargets", "RenderInputError", "project_views", "rasterize",
           "render_view", "boundary_mask", "chamfer_34", "ab_to_bins", "N_STATS", "N_BINS", "OTHERS", "TEMPLATE",
           "OVERLAP", "SUM_DI", "SUM_DT", "BOUNDARY", "BOUNDARY_OFF", "SUM_EDGE_DT", "BACKENDS"]
