"""Rasterising the posed body into each view and reducing it to likelihood statistics.

reference.py: the plain NumPy definition (also renders images for overlays); fast.py: the numba kernel
that computes the same statistics without keeping images. `statistics(..., backend=)` picks one.
numba is optional: backend "auto" uses it when it imports, else warns once and uses NumPy.
"""
import warnings

from .reference import (BOUNDARY, BOUNDARY_OFF, N_BINS, N_STATS, OVERLAP, SUM_DI, SUM_DT, SUM_EDGE_DT, TEMPLATE,
                        FrameTargets, RenderInputError, ab_to_bins, boundary_mask, chamfer_34, project_views,
                        rasterize, render_view)
from . import reference

BACKENDS = ("auto", "numpy", "fast")
_warned = False


def resolve_backend(backend="auto"):
    """"auto" | "numpy" | "fast" -> "numpy" or "fast" (the fast path needs numba)."""
    global _warned
    if backend not in BACKENDS:
        raise ValueError(f"unknown render backend {backend!r}; choose one of {BACKENDS}")
    if backend == "numpy":
        return "numpy"
    try:
        from . import fast  # noqa: F401  (imports numba)
    except ImportError as exc:
        if backend == "fast":
            raise ImportError(f"the fast render backend needs numba ({exc}); install numba or use backend='numpy'")
        if not _warned:
            warnings.warn(f"numba is not available ({exc}); the likelihood uses the slow NumPy path", RuntimeWarning)
            _warned = True
        return "numpy"
    return "fast"


def statistics(uv, z, faces, face_label, targets, need_chamfer=True, n_parts=0, cull=0, backend="auto"):
    """(P,C,N_STATS) statistics and (P,C,S,2,K) part histograms for projected meshes (see reference.py)."""
    if resolve_backend(backend) == "fast":
        from . import fast
        return fast.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)
    return reference.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)


def measure_vertices(vertices, cameras, faces, face_label, targets, need_chamfer=True, n_parts=0, cull=0,
                     backend="auto"):
    """Posed vertices (P,V,3) -> projection into every camera -> `statistics` (fast path: both in numba)."""
    if resolve_backend(backend) == "fast":
        from . import fast
        q, iz = fast.project_views(vertices, cameras)
        return fast.statistics_from_snapped(q, iz, faces, face_label, targets, need_chamfer, n_parts, cull)
    uv, z = project_views(vertices, cameras)
    return reference.statistics(uv, z, faces, face_label, targets, need_chamfer, n_parts, cull)


__all__ = ["statistics", "measure_vertices", "resolve_backend", "FrameTargets", "RenderInputError", "project_views", "rasterize",
           "render_view", "boundary_mask", "chamfer_34", "ab_to_bins", "N_STATS", "N_BINS", "TEMPLATE", "OVERLAP",
           "SUM_DI", "SUM_DT", "BOUNDARY", "BOUNDARY_OFF", "SUM_EDGE_DT", "BACKENDS"]
