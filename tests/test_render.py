"""The rasteriser and its statistics: hand-made cases with exact answers, and the fast path against the reference."""
import dataclasses

import numpy as np
import pytest

from markerless_mocap.core import render
from markerless_mocap.core.capture.camera import Camera
from markerless_mocap.core.render import fast, reference


# ---------------------------------------------------------------------------------------- helpers
def look_at(name, eye, target, f, width, height, dist=()):
    """OpenCV camera at `eye` looking at `target`, world Z up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    return Camera(name, K, np.asarray(dist, float), R, -R @ eye, width, height)


def sphere_mesh(n_lat=10, n_lon=16, radius=0.3):
    """A closed UV sphere whose latitude bands are 3 'parts' (labels 1..3)."""
    verts = [[0, 0, radius], [0, 0, -radius]]
    for i in range(1, n_lat):
        th = np.pi * i / n_lat
        for j in range(n_lon):
            ph = 2 * np.pi * j / n_lon
            verts.append([radius * np.sin(th) * np.cos(ph), radius * np.sin(th) * np.sin(ph), radius * np.cos(th)])
    verts = np.array(verts)

    def ring(i, j):
        return 2 + (i - 1) * n_lon + (j % n_lon)

    faces, band = [], []
    for j in range(n_lon):
        faces.append([0, ring(1, j), ring(1, j + 1)])
        band.append(0)
        faces.append([1, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)])
        band.append(n_lat - 1)
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [[a, c, b], [b, c, d]]
            band += [i, i]
    labels = (np.array(band) * 3 // n_lat + 1).astype(np.int16)
    return verts, np.array(faces), labels


def random_blob_targets(cameras, rng, n_blobs=3):
    """Observed features made of random ellipses, random edges and random colours."""
    import cv2

    H = max(c.height for c in cameras)
    W = max(c.width for c in cameras)
    C = len(cameras)
    sil = np.zeros((C, H, W), np.uint8)
    edge_off = np.ones((C, H, W), np.uint8)
    sil_dt = np.zeros((C, H, W))
    edge_dt = np.zeros((C, H, W))
    for c, cam in enumerate(cameras):
        s = np.zeros((cam.height, cam.width), np.uint8)
        for _ in range(n_blobs):
            centre = (int(rng.uniform(0.3, 0.7) * cam.width), int(rng.uniform(0.3, 0.7) * cam.height))
            axes = (int(rng.uniform(0.05, 0.2) * cam.width), int(rng.uniform(0.05, 0.2) * cam.height))
            cv2.ellipse(s, centre, axes, rng.uniform(0, 180), 0, 360, 1, -1)
        sil[c, :cam.height, :cam.width] = s
        e = rng.random((cam.height, cam.width)) < 0.1
        edge_off[c, :cam.height, :cam.width] = ~e
        sil_dt[c, :cam.height, :cam.width] = cv2.distanceTransform(1 - s, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        edge_dt[c, :cam.height, :cam.width] = np.minimum(
            cv2.distanceTransform((~e).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE), 5.0)
    ab = render.ab_to_bins(rng.uniform(-128, 127, (C, H, W, 2)))
    return render.FrameTargets([c.width for c in cameras], [c.height for c in cameras], sil, sil_dt, edge_off,
                               edge_dt, ab)


def square_uv(x0, y0, x1, y1):
    """Two triangles covering the axis-aligned square with these corners (pixel coordinates), depth 2."""
    uv = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    return uv, np.full(4, 2.0), np.array([[0, 1, 2], [0, 2, 3]])


# ---------------------------------------------------------------------------------------- rasterisation rules
def test_shared_edges_cover_every_pixel_centre_exactly_once():
    # Corners exactly on pixel centres: the top-left rule decides every tie.
    uv, z, faces = square_uv(2, 3, 12, 9)
    labels = render.rasterize(uv, z, faces, np.array([1, 2], np.int16), 16, 12)
    expected = np.zeros((12, 16), bool)
    expected[3:9, 2:12] = True  # top and left edges in, bottom and right out
    assert np.array_equal(labels > 0, expected)
    # The diagonal belongs to exactly one triangle: both labels present and their counts add up.
    assert (labels == 1).sum() + (labels == 2).sum() == 60
    assert (labels == 1).sum() > 0 and (labels == 2).sum() > 0
    # Winding order does not matter.
    flipped = render.rasterize(uv, z, faces[:, ::-1], np.array([1, 2], np.int16), 16, 12)
    assert np.array_equal(flipped, labels)


def test_fan_around_a_pixel_centre_owns_it_once():
    # Eight triangles meeting at the pixel centre (5, 5): it must be drawn by exactly one of them.
    centre = np.array([5.0, 5.0])
    ring = centre + 3 * np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 9)[:-1]])
    uv = np.vstack([centre, ring])
    faces = np.array([[0, 1 + k, 1 + (k + 1) % 8] for k in range(8)])
    z = np.full(9, 1.0)
    counts = np.zeros((11, 11), int)
    for k in range(8):
        counts += render.rasterize(uv, z, faces[k:k + 1], np.array([1], np.int16), 11, 11) > 0
    assert counts[5, 5] == 1
    assert counts.max() == 1


def test_depth_test_keeps_the_nearer_triangle_in_any_order():
    uv = np.array([[0, 0], [10, 0], [0, 10], [0, 0], [10, 0], [0, 10]], float) + 0.25
    z = np.array([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])  # second triangle nearer
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    for order in ([0, 1], [1, 0]):
        labels = render.rasterize(uv, z, faces[order], np.array([1, 2], np.int16)[order], 12, 12)
        assert set(np.unique(labels)) == {0, 2}


def test_triangles_behind_the_camera_are_not_drawn():
    uv, z, faces = square_uv(1.5, 1.5, 8.5, 8.5)
    z[1] = -1.0  # only the first triangle uses vertex 1
    labels = render.rasterize(uv, z, faces, np.array([1, 2], np.int16), 10, 10)
    assert set(np.unique(labels)) == {0, 2}


def test_boundary_is_four_neighbour_label_change_inside_the_body():
    labels = np.zeros((7, 8), np.int16)
    labels[1:6, 1:4] = 1
    labels[1:6, 4:7] = 2
    b = render.boundary_mask(labels)
    expected = np.zeros_like(b)
    expected[1:6, 1:7] = True
    expected[2:5, 2:3] = False  # interior of part 1
    expected[2:5, 5:6] = False  # interior of part 2
    assert np.array_equal(b, expected)
    # The image border is not a boundary.
    full = np.ones((4, 4), np.int16)
    assert not render.boundary_mask(full).any()


def test_chamfer_34_equals_the_chamfer_metric_by_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(5):
        mask = rng.random((17, 23)) < 0.03
        mask[rng.integers(17), rng.integers(23)] = True
        d = render.chamfer_34(mask)
        ys, xs = np.nonzero(mask)
        gy, gx = np.mgrid[:17, :23]
        dy = np.abs(gy[..., None] - ys)
        dx = np.abs(gx[..., None] - xs)
        brute = (3 * np.maximum(dx, dy) + np.minimum(dx, dy)).min(axis=-1) / 3.0
        assert np.array_equal(d, brute)
    # Within 8% of the Euclidean distance far from a point (the 3-4 mask's known bound).
    mask = np.zeros((41, 41), bool)
    mask[20, 20] = True
    gy, gx = np.mgrid[:41, :41]
    euclid = np.hypot(gy - 20, gx - 20)
    far = euclid > 5
    assert np.max(np.abs(render.chamfer_34(mask)[far] / euclid[far] - 1)) < 0.085


def test_project_views_matches_camera_projection_with_distortion():
    cams = [look_at("a", [3, 0, 0.5], [0, 0, 0], 500, 64, 48, dist=[-0.2, 0.05, 0.001, -0.002, 0.01]),
            look_at("b", [0, 3, 0.2], [0, 0, 0], 400, 80, 60)]
    pts = np.random.default_rng(2).normal(0, 0.3, (5, 7, 3))
    uv, z = render.project_views(pts, cams)
    for c, cam in enumerate(cams):
        ref_uv, ref_z = cam.project_with_depth(pts)
        assert np.allclose(uv[:, c], ref_uv, atol=1e-9)
        assert np.allclose(z[:, c], ref_z, atol=1e-12)
    # The numba projection returns the same points snapped to the subpixel grid (summation order may move
    # a point that sits on a rounding boundary by one subpixel), and 1/z.
    pts[0, 0] = [3, 0, 0.5]  # at camera a's centre: not drawable there
    uv, z = render.project_views(pts, cams)
    q_ref, usable = reference.snap(uv)
    q, iz = fast.project_views(pts, cams)
    drawable = usable & (z > reference.Z_NEAR)
    assert np.abs(q - q_ref)[drawable].max() <= 1
    assert np.allclose(iz[drawable], 1 / z[drawable], rtol=1e-14)
    assert np.all(iz[~drawable] == 0) and not drawable[0, 0, 0]


# ---------------------------------------------------------------------------------------- statistics
def _targets_with_square(width, height, rows, cols, chamfer_cap=np.inf):
    import cv2

    sil = np.zeros((1, height, width), np.uint8)
    sil[0, rows, cols] = 1
    dt = cv2.distanceTransform(1 - sil[0], cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[None].astype(float)
    zeros = np.zeros((1, height, width))
    return render.FrameTargets([width], [height], sil, dt, np.ones_like(sil), zeros,
                               np.zeros((1, height, width, 2), np.uint8), chamfer_cap=chamfer_cap)


@pytest.mark.parametrize("backend", ["numpy", "fast"])
def test_square_against_shifted_square_has_known_xor_and_chamfer_sums(backend):
    # Template: columns 10..19, rows 5..14 (100 px). Observed: the same square 4 px to the right.
    uv, z, faces = square_uv(9.5, 4.5, 19.5, 14.5)
    targets = _targets_with_square(40, 24, slice(5, 15), slice(14, 24))
    stats, _ = render.statistics(uv[None, None], z[None, None], faces, np.array([1, 1], np.int16), targets,
                                 backend=backend)
    s = stats[0, 0]
    assert s[render.TEMPLATE] == 100
    assert s[render.OVERLAP] == 60  # XOR = 100 + 100 - 2 * 60 = 80
    # Template columns 10..13 lie 4, 3, 2, 1 px left of the observed square: 10 rows each.
    assert s[render.SUM_DI] == pytest.approx(10 * (4 + 3 + 2 + 1))
    # Observed columns 20..23 lie 1..4 px right of the template (horizontal: chamfer is exact).
    assert s[render.SUM_DT] == pytest.approx(10 * (1 + 2 + 3 + 4))
    assert s[render.BOUNDARY] == 36


@pytest.mark.parametrize("backend", ["numpy", "fast"])
def test_chamfer_cap_truncates_each_observed_pixel_distance(backend):
    # As above, with observed pixels counted up to 2 px: columns 20..23 give 1, 2, 2, 2 per row.
    uv, z, faces = square_uv(9.5, 4.5, 19.5, 14.5)
    targets = _targets_with_square(40, 24, slice(5, 15), slice(14, 24), chamfer_cap=2.0)
    stats, _ = render.statistics(uv[None, None], z[None, None], faces, np.array([1, 1], np.int16), targets,
                                 backend=backend)
    assert stats[0, 0, render.SUM_DT] == pytest.approx(10 * (1 + 2 + 2 + 2))
    assert stats[0, 0, render.SUM_DI] == pytest.approx(10 * (4 + 3 + 2 + 1))  # the other sum is not capped
    with pytest.raises(render.RenderInputError, match="chamfer_cap"):
        _targets_with_square(40, 24, slice(5, 15), slice(14, 24), chamfer_cap=0.0)


def test_fast_path_equals_reference_on_random_poses_and_views_of_different_sizes():
    verts, faces, labels = sphere_mesh()
    rng = np.random.default_rng(3)
    cams = [look_at("a", [2.5, 0.3, 0.4], [0, 0, 0], 120, 64, 48),
            look_at("b", [-0.5, 2.2, -0.3], [0, 0, 0], 90, 40, 56),
            look_at("c", [0.2, -1.8, 1.0], [0, 0, 0], 70, 50, 50, dist=[-0.1, 0.01, 0, 0, 0])]
    targets = random_blob_targets(cams, rng)
    P = 12
    poses = []
    for _ in range(P):
        A = np.linalg.qr(rng.normal(size=(3, 3)))[0] * rng.uniform(0.6, 1.6, 3)
        poses.append(verts @ A.T + rng.normal(0, 0.35, 3))
    poses.append(verts * 0.2 + [2.4, 0.3, 0.4])  # partly behind camera a
    poses.append(verts + [0, 0, 10])  # out of every view
    uv, z = render.project_views(np.array(poses), cams)
    capped = dataclasses.replace(targets, chamfer_cap=4.0)
    for cull, case_targets in ((0, targets), (1, targets), (-1, targets), (0, capped)):
        s_ref, h_ref = reference.statistics(uv, z, faces, labels, case_targets, True, 3, cull)
        s_fast, h_fast = fast.statistics(uv, z, faces, labels, case_targets, True, 3, cull)
        assert np.array_equal(s_ref[..., render.TEMPLATE], s_fast[..., render.TEMPLATE])
        assert np.allclose(s_ref, s_fast, rtol=1e-12, atol=1e-9)
        assert np.array_equal(h_ref, h_fast)
    assert s_ref[:P, :, render.TEMPLATE].min() > 0  # the random poses are actually seen
    assert np.all(s_ref[-1, :, render.TEMPLATE] == 0)


def test_fast_path_equals_reference_for_triangles_reaching_far_outside_the_image():
    # The fast pixel loop steps edge functions in floats only while every vertex is within
    # fast._FLOAT_EXACT_COORD (65536 px); a vertex beyond it (near the camera plane) takes the integer loop.
    rng = np.random.default_rng(5)
    cams = [look_at("a", [2.5, 0.3, 0.4], [0, 0, 0], 120, 64, 48)]
    targets = random_blob_targets(cams, rng)
    limit_px = fast._FLOAT_EXACT_COORD / reference.SUBPIXEL
    # Two small triangles in front of the big one, crossing each other in depth, their corners on pixel
    # centres and one along a row of them (the top-left rule decides those pixels), drawn by the same loop.
    small = [[10.0, 10.0], [40.0, 10.0], [16.0, 40.0], [12.0, 38.0], [38.0, 14.0], [42.0, 36.0]]
    uv, z = [], []
    for far in (3e5, 0.9 * limit_px, 1.1 * limit_px):
        uv.append([[-far, -0.7 * far], [far, 30.3], [20.7, 1.3 * far]] + small)
        z.append([2.0, 2.5, 3.0, 1.0, 1.6, 1.3, 1.7, 1.0, 1.2])
    uv, z = np.array(uv, float)[:, None], np.array(z)[:, None]
    faces, labels = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]]), np.array([1, 2, 3], np.int16)
    for cull in (0, 1, -1):
        s_ref, h_ref = reference.statistics(uv, z, faces, labels, targets, True, 3, cull)
        s_fast, h_fast = fast.statistics(uv, z, faces, labels, targets, True, 3, cull)
        assert np.array_equal(s_ref[..., render.TEMPLATE], s_fast[..., render.TEMPLATE])
        assert np.allclose(s_ref, s_fast, rtol=1e-12, atol=1e-9)
        assert np.array_equal(h_ref, h_fast)
    s_ref, h_ref = reference.statistics(uv, z, faces, labels, targets, True, 3, 0)
    assert np.all(s_ref[:, 0, render.TEMPLATE] == 64 * 48)  # the big triangle covers the whole image
    assert np.all(h_ref[:, 0, 1:, 0].sum(axis=-1) > 100)  # both small ones show over it


def test_fast_path_matches_reference_on_the_body_at_the_energy_resolution(bpy_module):
    from rig_helpers import load_subject, subject_blend_path

    if not subject_blend_path().is_file():
        pytest.skip(f"no sample subject at {subject_blend_path()} (set MOCAP_TEST_SUBJECT)")

    from markerless_mocap.addon.scene_bridge import body_from_blender
    from markerless_mocap.core.body.proxy import make_proxy

    arm, mesh = load_subject(bpy_module)
    body = body_from_blender(arm, mesh)
    proxy = make_proxy(body, 2000)
    cams = [look_at(f"c{i}", [3.5 * np.cos(a), 3.5 * np.sin(a), 1.2], body.default_pose()[:3],
                    550, 640, 480).scaled(0.5)
            for i, a in enumerate(np.deg2rad([20, 110, 200, 290]))]
    rng = np.random.default_rng(4)
    targets = random_blob_targets(cams, rng)
    x0 = body.default_pose()
    lo = np.where(np.isfinite(body.lower), body.lower, -0.3)
    hi = np.where(np.isfinite(body.upper), body.upper, 0.3)
    poses = np.tile(x0, (4, 1))
    poses[:, 6:] = rng.uniform(lo[6:], hi[6:], (4, body.n_dof - 6)) * 0.5
    uv, z = render.project_views(proxy.deform(body, poses), cams)
    labels = (proxy.face_part + 1).astype(np.int16)
    s_ref, h_ref = reference.statistics(uv, z, proxy.faces, labels, targets, True, len(proxy.part_names))
    s_fast, h_fast = fast.statistics(uv, z, proxy.faces, labels, targets, True, len(proxy.part_names))
    n_ref = s_ref[..., render.TEMPLATE]
    assert n_ref.min() > 500
    assert np.all(np.abs(s_fast[..., render.TEMPLATE] - n_ref) <= 0.005 * n_ref)
    assert np.allclose(s_ref, s_fast, rtol=1e-9, atol=1e-6)
    assert np.array_equal(h_ref, h_fast)


def test_frame_targets_reject_mismatched_shapes():
    z = np.zeros((2, 10, 12))
    with pytest.raises(render.RenderInputError, match="ab_bins"):
        render.FrameTargets([12, 12], [10, 10], z, z, z, z, np.zeros((2, 10, 12, 3)))
    with pytest.raises(render.RenderInputError, match="width and height"):
        render.FrameTargets([13, 12], [10, 10], z, z, z, z, np.zeros((2, 10, 12, 2)))


def test_unknown_backend_is_rejected_with_the_choices():
    with pytest.raises(ValueError, match="numpy"):
        render.resolve_backend("cuda")


_PROBE = """
import importlib, sys
import numpy as np
fast = importlib.import_module(sys.argv[1] + ".core.render.fast")
ref = importlib.import_module(sys.argv[1] + ".core.render.reference")
uv = np.array([[[[2.5, 2.5], [9.5, 2.5], [9.5, 7.5], [2.5, 7.5]]]])
z = np.full((1, 1, 4), 2.0)
t = ref.FrameTargets([12], [10], np.zeros((1, 10, 12)), np.zeros((1, 10, 12)), np.ones((1, 10, 12)),
                     np.zeros((1, 10, 12)), np.zeros((1, 10, 12, 2)))
stats, _ = fast.statistics(uv, z, np.array([[0, 1, 2], [0, 2, 3]]), np.array([1, 1]), t)
assert stats[0, 0, 0] == 35, stats
"""


@pytest.mark.slow
def test_jit_cache_works_when_the_package_is_imported_under_two_names(tmp_path):
    # The CLI imports `markerless_mocap`, Blender `bl_ext.<repo>.markerless_mocap`: numba's cached code names
    # its module, so each name needs its own cache (else: ModuleNotFoundError on the second name).
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    probe = tmp_path / "probe.py"
    probe.write_text(_PROBE)
    for name in ("markerless_mocap", "mocap_cache_probe"):
        (tmp_path / name).mkdir()
        (tmp_path / name / name).symlink_to(repo, target_is_directory=True)
    for name in ("markerless_mocap", "mocap_cache_probe", "markerless_mocap", "mocap_cache_probe"):
        run = subprocess.run([sys.executable, str(probe), name], cwd=tmp_path / name, capture_output=True, text=True,
                             env={**__import__("os").environ, "PYTHONPATH": str(tmp_path / name)}, timeout=300)
        assert run.returncode == 0, run.stderr[-2000:]


def test_auto_backend_falls_back_to_numpy_with_a_warning_without_numba(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "numba", None)  # `import numba` raises ImportError
    monkeypatch.delitem(sys.modules, fast.__name__)
    monkeypatch.delattr(render, "fast", raising=False)
    monkeypatch.setattr(render, "_warned", False)
    with pytest.warns(RuntimeWarning, match="numba"):
        assert render.resolve_backend("auto") == "numpy"
    with pytest.raises(ImportError, match="backend='numpy'"):
        render.resolve_backend("fast")
    uv, z, faces = square_uv(1.5, 1.5, 6.5, 6.5)
    targets = _targets_with_square(10, 10, slice(2, 7), slice(2, 7))
    stats, _ = render.statistics(uv[None, None], z[None, None], faces, np.array([1, 1], np.int16), targets)
    assert stats[0, 0, render.OVERLAP] == 25
