"""The fast likelihood statistics: one numba kernel, parallel over pose x view, no images kept.

Same rules and same statistics as reference.py (read its docstring first). Edge functions are exact
integers on the 1/256 px grid (here stepped incrementally along each row, in floats where they are small
enough to be exact there) and 1/z uses the same float operations in the same order, so both paths give
identical label images from the same projected points.
`project_views` projects and snaps the posed vertices for all pose x camera pairs in parallel as well
(checked against reference.project_views = Camera.project_with_depth + reference.snap).

Per task (one pose in one view) a worker reuses its own label / 1/z / chamfer buffers and touches only
  * the template's bounding box (+1 pixel ring, its labels cleared before drawing, so no full-image clears;
    the 1/z buffer is never cleared: a pixel without a label takes any depth),
  * each triangle's own bounding box while rasterising,
  * the union of the template and observed boxes for the template chamfer transform (only when the
    Chamfer silhouette term is on): the 3-4 chamfer distance between two pixels is realised by a
    staircase path inside their bounding box, so the two-pass transform on that box is exact there.
"""
from __future__ import annotations

import numba
import numpy as np
from numba import prange

from ..jit import jit
from .reference import (BOUNDARY, BOUNDARY_OFF, MAX_COORD_PX, N_BINS, N_STATS, OTHERS, OVERLAP, SUBPIXEL, SUM_DI,
                        SUM_DT, SUM_EDGE_DT, TEMPLATE, Z_NEAR, FrameTargets, snap)

_BIG = 1 << 28  # 'no template pixel yet' in the int32 chamfer buffer (x3 units: ~90 million px)


def _chunks_one_at_a_time():
    """Dynamic scheduling of prange iterations (numba >= 0.57); a no-op context on older numba."""
    import contextlib

    chunksize = getattr(numba, "parallel_chunksize", None)
    return chunksize(1) if chunksize is not None else contextlib.nullcontext()


# Below this many 1/SUBPIXEL units every edge-function value of a triangle (products of two coordinate
# differences, each under 2^25) is an integer under 2^51, so float64 holds it exactly: the pixel loop then steps
# floats, which gives the same inside tests and the same 1/z as integers converted per pixel, ~9 % sooner
# (docs/defaults.md, "_FLOAT_EXACT_COORD").
_FLOAT_EXACT_COORD = 1 << 24


@jit()
def _fill_float(ax, ay, bx, by, cx, cy, e0x, e0y, e1x, e1y, e2x, e2y, t0, t1, t2, iza, izb, izc, inv_area, lab,
                x0, x1, y0, y1, labels, zbuf):
    """Draw one triangle's pixels with the edge functions held in floats (exact here, see _FLOAT_EXACT_COORD)."""
    s0, s1, s2 = float(e0y * SUBPIXEL), float(e1y * SUBPIXEL), float(e2y * SUBPIXEL)  # change per pixel step in x
    ft0, ft1, ft2 = float(t0), float(t1), float(t2)
    sx0 = x0 * SUBPIXEL
    for y in range(y0, y1 + 1):
        sy = y * SUBPIXEL
        w0 = float(e0x * (sy - by) - e0y * (sx0 - bx))
        w1 = float(e1x * (sy - cy) - e1y * (sx0 - cx))
        w2 = float(e2x * (sy - ay) - e2y * (sx0 - ax))
        # Branch-free body (selects, no jumps): the inside pattern of tiny triangles is unpredictable.
        for x in range(x0, x1 + 1):
            inv_z = (w0 * iza + w1 * izb + w2 * izc) * inv_area
            old = zbuf[y, x]
            prev = labels[y, x]
            # An empty pixel (label 0) takes any depth: the depth buffer needs no clearing (inv_z > 0
            # inside a drawable triangle, so this is the test against a buffer of zeros).
            closer = (w0 >= ft0) & (w1 >= ft1) & (w2 >= ft2) & ((prev == 0) | (inv_z > old))
            zbuf[y, x] = inv_z if closer else old
            labels[y, x] = lab if closer else prev
            w0 -= s0
            w1 -= s1
            w2 -= s2


@jit()
def _fill_int(ax, ay, bx, by, cx, cy, e0x, e0y, e1x, e1y, e2x, e2y, t0, t1, t2, iza, izb, izc, inv_area, lab,
              x0, x1, y0, y1, labels, zbuf):
    """_fill_float with integer edge functions, for triangles reaching far outside the image (a vertex
    near the camera plane): their products can exceed what a float holds exactly. Kept as a second loop, not
    a flag in one: one loop with both number types measured ~3 % slower on the search's batches."""
    s0, s1, s2 = e0y * SUBPIXEL, e1y * SUBPIXEL, e2y * SUBPIXEL
    sx0 = x0 * SUBPIXEL
    for y in range(y0, y1 + 1):
        sy = y * SUBPIXEL
        w0 = e0x * (sy - by) - e0y * (sx0 - bx)
        w1 = e1x * (sy - cy) - e1y * (sx0 - cx)
        w2 = e2x * (sy - ay) - e2y * (sx0 - ax)
        for x in range(x0, x1 + 1):
            inv_z = (float(w0) * iza + float(w1) * izb + float(w2) * izc) * inv_area
            old = zbuf[y, x]
            prev = labels[y, x]
            closer = (((w0 - t0) | (w1 - t1) | (w2 - t2)) >= 0) & ((prev == 0) | (inv_z > old))
            zbuf[y, x] = inv_z if closer else old
            labels[y, x] = lab if closer else prev
            w0 -= s0
            w1 -= s1
            w2 -= s2


@jit()
def _rasterize(q, iz, faces, face_label, cull, w, h, labels, zbuf, row_lo, row_hi, small_coords):
    """Draw one mesh (vertices snapped to 1/SUBPIXEL px, `q`; iz = 0 marks unusable vertices) into
    labels/zbuf (labels zero over the template box, zbuf read only where a label is set); widen each row's
    span to cover what it draws."""
    for f in range(faces.shape[0]):
        ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
        iza, izb, izc = iz[ia], iz[ib], iz[ic]
        if iza <= 0.0 or izb <= 0.0 or izc <= 0.0:
            continue
        ax, ay, bx, by, cx, cy = q[ia, 0], q[ia, 1], q[ib, 0], q[ib, 1], q[ic, 0], q[ic, 1]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0 or cull * area < 0:
            continue
        if area < 0:
            bx, by, cx, cy = cx, cy, bx, by
            izb, izc = izc, izb
            area = -area
        x0 = max(0, -((-min(ax, min(bx, cx))) // SUBPIXEL))
        x1 = min(w - 1, max(ax, max(bx, cx)) // SUBPIXEL)
        if x1 < x0:
            continue
        y0 = max(0, -((-min(ay, min(by, cy))) // SUBPIXEL))
        y1 = min(h - 1, max(ay, max(by, cy)) // SUBPIXEL)
        if y1 < y0:
            continue
        e0x, e0y = cx - bx, cy - by
        e1x, e1y = ax - cx, ay - cy
        e2x, e2y = bx - ax, by - ay
        # Top-left rule: w >= 0 on edges the triangle owns, w >= 1 (w > 0) on the others; then one sign
        # test covers all three: (w0 - t0) | (w1 - t1) | (w2 - t2) >= 0.
        t0 = 0 if (e0y < 0 or (e0y == 0 and e0x > 0)) else 1
        t1 = 0 if (e1y < 0 or (e1y == 0 and e1x > 0)) else 1
        t2 = 0 if (e2y < 0 or (e2y == 0 and e2x > 0)) else 1
        inv_area = 1.0 / float(area)
        lab = face_label[f]
        if small_coords:
            _fill_float(ax, ay, bx, by, cx, cy, e0x, e0y, e1x, e1y, e2x, e2y, t0, t1, t2, iza, izb, izc, inv_area,
                        lab, x0, x1, y0, y1, labels, zbuf)
        else:
            _fill_int(ax, ay, bx, by, cx, cy, e0x, e0y, e1x, e1y, e2x, e2y, t0, t1, t2, iza, izb, izc, inv_area,
                      lab, x0, x1, y0, y1, labels, zbuf)
        for y in range(y0, y1 + 1):  # conservative drawn span of each row (the box), for the statistics pass
            if x0 < row_lo[y]:
                row_lo[y] = x0
            if x1 > row_hi[y]:
                row_hi[y] = x1


@jit()
def _chamfer_sum(labels, ty0, ty1, tx0, tx1, obs, oy0, oy1, ox0, ox1, dt, cap_units):
    """Sum over observed pixels of the 3-4 chamfer distance (pixels) to the template, each capped at
    cap_units / 3 pixels.

    dt is (H+2, W+2): image pixel (y, x) lives at dt[y+1, x+1], so the ring of _BIG around the box
    replaces every bounds test in the two passes.
    """
    uy0, uy1 = min(ty0, oy0), max(ty1, oy1)
    ux0, ux1 = min(tx0, ox0), max(tx1, ox1)
    for y in range(uy0, uy1 + 3):  # the box and its ring (buffer coordinates)
        for x in range(ux0, ux1 + 3):
            dt[y, x] = _BIG
    for y in range(ty0, ty1 + 1):
        for x in range(tx0, tx1 + 1):
            if labels[y, x] > 0:
                dt[y + 1, x + 1] = 0
    for y in range(uy0 + 1, uy1 + 2):
        for x in range(ux0 + 1, ux1 + 2):
            dt[y, x] = min(dt[y, x], dt[y - 1, x - 1] + 4, dt[y - 1, x] + 3, dt[y - 1, x + 1] + 4,
                           dt[y, x - 1] + 3)
    total = 0
    for y in range(uy1 + 1, uy0, -1):
        for x in range(ux1 + 1, ux0, -1):
            v = min(dt[y, x], dt[y + 1, x - 1] + 4, dt[y + 1, x] + 3, dt[y + 1, x + 1] + 4, dt[y, x + 1] + 3)
            dt[y, x] = v
            total += min(v, cap_units) * (obs[y - 1, x - 1] == 1)  # observed pixels only (not OTHERS)
    return total / 3.0


@jit()
def _one_task(q, iz, faces, face_label, cull, w, h, sil, sil_dt, edge_off, edge_dt, ab_bins, obox,
              need_chamfer, cap_units, need_color, labels, zbuf, dt, row_lo, row_hi, stats_out, hist_out):
    # Template box: the pixel centres the usable vertices span (every drawn pixel lies inside).
    big = 1 << 62
    xmin, xmax, ymin, ymax = big, -big, big, -big
    for v in range(q.shape[0]):
        if iz[v] > 0.0:
            xmin = min(xmin, q[v, 0])
            xmax = max(xmax, q[v, 0])
            ymin = min(ymin, q[v, 1])
            ymax = max(ymax, q[v, 1])
    if xmin > xmax:
        return
    tx0 = max(0, -((-xmin) // SUBPIXEL))
    tx1 = min(w - 1, xmax // SUBPIXEL)
    ty0 = max(0, -((-ymin) // SUBPIXEL))
    ty1 = min(h - 1, ymax // SUBPIXEL)
    if tx1 < tx0 or ty1 < ty0:
        return
    for y in range(max(0, ty0 - 1), min(h - 1, ty1 + 1) + 1):
        row_lo[y] = w
        row_hi[y] = -1
        for x in range(max(0, tx0 - 1), min(w - 1, tx1 + 1) + 1):
            labels[y, x] = 0
    # every usable vertex and pixel within _FLOAT_EXACT_COORD: the float pixel loop is exact for every triangle
    small_coords = max(-xmin, xmax, -ymin, ymax, w * SUBPIXEL, h * SUBPIXEL) < _FLOAT_EXACT_COORD
    _rasterize(q, iz, faces, face_label, cull, w, h, labels, zbuf, row_lo, row_hi, small_coords)
    n_t = 0
    n_overlap = 0
    sum_di = 0.0
    n_b = 0
    n_off = 0
    sum_edt = 0.0
    for y in range(ty0, ty1 + 1):
        ym, yp = max(y - 1, 0), min(y + 1, h - 1)  # at the image border the pixel is its own neighbour
        for x in range(row_lo[y], row_hi[y] + 1):  # only the drawn span of the row
            lab = labels[y, x]
            if lab == 0:
                continue
            xm, xp = max(x - 1, 0), min(x + 1, w - 1)
            s_obs = sil[y, x]
            if s_obs != OTHERS:  # another actor's pixel counts for nothing (reference.py)
                n_t += 1
                n_overlap += s_obs
                sum_di += sil_dt[y, x]
            b = ((labels[ym, x] != lab) | (labels[yp, x] != lab) | (labels[y, xm] != lab)
                 | (labels[y, xp] != lab))
            n_b += b
            n_off += b * edge_off[y, x]
            sum_edt += b * edge_dt[y, x]
            if need_color and s_obs != OTHERS:
                s = lab - 1
                hist_out[s, 0, ab_bins[y, x, 0]] += 1
                hist_out[s, 1, ab_bins[y, x, 1]] += 1
    stats_out[TEMPLATE] = n_t
    stats_out[OVERLAP] = n_overlap
    stats_out[SUM_DI] = sum_di
    stats_out[BOUNDARY] = n_b
    stats_out[BOUNDARY_OFF] = n_off
    stats_out[SUM_EDGE_DT] = sum_edt
    if need_chamfer and n_t > 0 and obox[1] >= obox[0]:
        stats_out[SUM_DT] = _chamfer_sum(labels, ty0, ty1, tx0, tx1, sil, obox[0], obox[1], obox[2], obox[3], dt,
                                          cap_units)


@jit(parallel=True)
def _statistics_kernel(q, iz, faces, face_label, cull, widths, heights, sil, sil_dt, edge_off, edge_dt, ab_bins,
                       obox, need_chamfer, cap_units, need_color, n_chunks, stats, hist):
    P, C = q.shape[0], q.shape[1]
    H, W = sil.shape[1], sil.shape[2]
    n_tasks = P * C
    for chunk in prange(n_chunks):
        # One set of buffers per chunk, reused by all its tasks (tasks are dealt round-robin). Left
        # uninitialised: each task clears (or fills) exactly the region it later reads.
        labels = np.empty((H, W), dtype=np.int16)
        zbuf = np.empty((H, W), dtype=np.float64)
        dt = np.empty((H + 2, W + 2) if need_chamfer else (1, 1), dtype=np.int32)
        row_lo = np.empty(H, dtype=np.int64)
        row_hi = np.empty(H, dtype=np.int64)
        for task in range(chunk, n_tasks, n_chunks):
            p = task // C
            c = task % C
            _one_task(q[p, c], iz[p, c], faces, face_label, cull, widths[c], heights[c], sil[c], sil_dt[c],
                      edge_off[c], edge_dt[c], ab_bins[c], obox[c], need_chamfer, cap_units, need_color, labels, zbuf,
                      dt, row_lo, row_hi, stats[p, c], hist[p, c])


def statistics(uv, z, faces, face_label, targets: FrameTargets, need_chamfer=True, n_parts=0, cull=0):
    """Fast path with the reference's signature and results: (P,C,N_STATS) and (P,C,S,2,K)."""
    q, usable = snap(uv)
    z = np.asarray(z, dtype=np.float64)
    with np.errstate(divide="ignore"):
        iz = np.where(usable & (z > Z_NEAR), 1.0 / z, 0.0)  # 0 marks "do not draw"
    return statistics_from_snapped(q, iz, faces, face_label, targets, need_chamfer, n_parts, cull)


# ---------------------------------------------------------------------------------------- projection
@jit(parallel=True)
def _project_kernel(vertices, R, t, K, dist, has_dist, q, iz):
    P, V = vertices.shape[0], vertices.shape[1]
    C = R.shape[0]
    for task in prange(P * C):
        p = task // C
        c = task % C
        # The camera in locals: read from the arrays inside the vertex loop they were loaded again for every
        # vertex (the compiler cannot tell that the writes to q and iz leave them alone).
        r00, r01, r02, t0 = R[c, 0, 0], R[c, 0, 1], R[c, 0, 2], t[c, 0]
        r10, r11, r12, t1 = R[c, 1, 0], R[c, 1, 1], R[c, 1, 2], t[c, 1]
        r20, r21, r22, t2 = R[c, 2, 0], R[c, 2, 1], R[c, 2, 2], t[c, 2]
        fx, skew, cx, fy, cy = K[c, 0, 0], K[c, 0, 1], K[c, 0, 2], K[c, 1, 1], K[c, 1, 2]
        k1, k2, p1, p2, k3, k4, k5, k6 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3], dist[c, 4], dist[c, 5], \
            dist[c, 6], dist[c, 7]
        s1, s2, s3, s4 = dist[c, 8], dist[c, 9], dist[c, 10], dist[c, 11]
        distorted = has_dist[c]
        rational = k4 != 0.0 or k5 != 0.0 or k6 != 0.0  # most calibrations have neither of these two parts
        prism = s1 != 0.0 or s2 != 0.0 or s3 != 0.0 or s4 != 0.0
        for v in range(V):
            X, Y, Z = vertices[p, v, 0], vertices[p, v, 1], vertices[p, v, 2]
            zc = r20 * X + r21 * Y + r22 * Z + t2
            if zc <= Z_NEAR:
                iz[p, c, v] = 0.0
                q[p, c, v, 0] = 0
                q[p, c, v, 1] = 0
                continue
            inv_z = 1.0 / zc
            x = (r00 * X + r01 * Y + r02 * Z + t0) * inv_z
            y = (r10 * X + r11 * Y + r12 * Z + t1) * inv_z
            if distorted:  # OpenCV's full model, as Camera.distort_normalized
                r2 = x * x + y * y
                radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
                if rational:
                    radial /= 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
                xy2 = 2 * x * y
                xd = x * radial + p1 * xy2 + p2 * (r2 + 2 * x * x)
                yd = y * radial + p1 * (r2 + 2 * y * y) + p2 * xy2
                if prism:
                    r4 = r2 * r2
                    xd += s1 * r2 + s2 * r4
                    yd += s3 * r2 + s4 * r4
                x, y = xd, yd
            u = fx * x + skew * y + cx
            w = fy * y + cy
            if abs(u) <= MAX_COORD_PX and abs(w) <= MAX_COORD_PX:  # as reference.snap
                q[p, c, v, 0] = int(np.rint(u * SUBPIXEL))
                q[p, c, v, 1] = int(np.rint(w * SUBPIXEL))
                iz[p, c, v] = inv_z
            else:
                q[p, c, v, 0] = 0
                q[p, c, v, 1] = 0
                iz[p, c, v] = 0.0


def project_views(vertices, cameras):
    """(P,V,3) world vertices -> snapped pixels (P,C,V,2) int64 in 1/SUBPIXEL px and inverse depths (P,C,V),
    0 where a vertex cannot be drawn (z <= Z_NEAR or beyond MAX_COORD_PX).

    Same model as reference.project_views (Camera.project_with_depth) followed by reference.snap, parallel
    over pose x camera, without the NumPy temporaries that dominate the vectorised version.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    C = len(cameras)
    R = np.array([c.R for c in cameras], dtype=np.float64)
    t = np.array([c.t for c in cameras], dtype=np.float64)
    K = np.array([c.K for c in cameras], dtype=np.float64)
    dist = np.zeros((C, 12))
    for i, c in enumerate(cameras):
        dist[i, :c.dist.size] = c.dist
    has_dist = np.array([bool(np.any(c.dist)) for c in cameras])
    P, V = vertices.shape[:2]
    q = np.empty((P, C, V, 2), dtype=np.int64)
    iz = np.empty((P, C, V))
    _project_kernel(vertices, R, t, K, dist, has_dist, q, iz)
    return q, iz


def statistics_from_snapped(q, iz, faces, face_label, targets: FrameTargets, need_chamfer=True, n_parts=0, cull=0):
    """`statistics` for the output of fast.project_views (snapped pixels, inverse depths, 0 = do not draw)."""
    P, C = q.shape[:2]
    stats = np.zeros((P, C, N_STATS))
    hist = np.zeros((P, C, max(n_parts, 1), 2, N_BINS), dtype=np.int32)  # dummy part when colour is off
    # Many small chunks handed out one at a time: a thread that the OS (or a busy machine) slows down
    # does not hold up the others.
    n_chunks = max(1, min(P * C, 8 * numba.get_num_threads()))
    with _chunks_one_at_a_time():
        _statistics_kernel(np.ascontiguousarray(q, dtype=np.int64), np.ascontiguousarray(iz, dtype=np.float64),
                           np.ascontiguousarray(faces, dtype=np.int64),
                           np.ascontiguousarray(face_label, dtype=np.int16),
                           int(cull), targets.widths, targets.heights, targets.silhouette, targets.silhouette_dt,
                           targets.edge_off, targets.edge_dt, targets.ab_bins, targets.observed_box, bool(need_chamfer),
                           np.int64(targets.chamfer_cap_units), bool(n_parts), n_chunks, stats, hist)
    if not n_parts:
        hist = hist[:, :, :0]
    return stats, hist


# ---------------------------------------------------------------------------------------- coverage
@jit()
def _coverage_kernel(uv, z, faces, width, height, z_near, mask):
    for f in range(faces.shape[0]):
        ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
        if min(z[ia], min(z[ib], z[ic])) <= z_near:
            continue
        ax, ay, bx, by, cx, cy = uv[ia, 0], uv[ia, 1], uv[ib, 0], uv[ib, 1], uv[ic, 0], uv[ic, 1]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0 or not np.isfinite(area):
            continue
        # The box of rim._pixel_samples: clipped to [-1, size] first, then to the image.
        x0 = max(int(np.ceil(min(max(min(ax, min(bx, cx)), -1.0), width))), 0)
        x1 = min(int(np.floor(min(max(max(ax, max(bx, cx)), -1.0), width))), width - 1)
        y0 = max(int(np.ceil(min(max(min(ay, min(by, cy)), -1.0), height))), 0)
        y1 = min(int(np.floor(min(max(max(ay, max(by, cy)), -1.0), height))), height - 1)
        s = 1.0 / area
        for y in range(y0, y1 + 1):
            fy = float(y)
            for x in range(x0, x1 + 1):
                if mask[y, x]:
                    continue
                fx = float(x)
                wa = ((bx - fx) * (cy - fy) - (by - fy) * (cx - fx)) * s
                wb = ((cx - fx) * (ay - fy) - (cy - fy) * (ax - fx)) * s
                wc = 1.0 - wa - wb
                if wa >= 0 and wb >= 0 and wc >= 0:
                    mask[y, x] = True


def coverage(uv, z, faces, width, height):
    """rim.coverage (pixel centres inside any triangle in front of Z_NEAR, either winding) with the same
    floating-point tests, triangle by triangle instead of all candidate pixels at once."""
    mask = np.zeros((height, width), dtype=np.bool_)
    _coverage_kernel(np.ascontiguousarray(uv, dtype=np.float64), np.ascontiguousarray(z, dtype=np.float64),
                     np.ascontiguousarray(faces, dtype=np.int64), int(width), int(height), float(Z_NEAR), mask)
    return mask
