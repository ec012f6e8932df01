"""Camera model: projection against cv2.projectPoints, scaling, undistortion, Blender conversion."""
import cv2
import numpy as np
import pytest

from markerless_mocap.core.capture.camera import (Camera, CameraError, camera_from_blender, camera_to_blender,
                                                  matrix_to_rodrigues, rodrigues_to_matrix)


def random_camera(rng, width=640, height=480, fx=800.0, fy=None, n_dist=0, dist_scale=0.05, name="cam"):
    """A camera at ~5 m from the origin looking roughly at it, with a random principal point."""
    fy = fx if fy is None else fy
    rvec = rng.normal(scale=0.4, size=3)
    R = rodrigues_to_matrix(rvec)
    t = np.array([0.0, 0.0, 5.0]) + rng.normal(scale=0.3, size=3)
    cx = width / 2 + rng.uniform(-0.15, 0.15) * width
    cy = height / 2 + rng.uniform(-0.15, 0.15) * height
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    dist = rng.normal(scale=dist_scale, size=n_dist)
    return Camera(name, K, dist, R, t, width, height)


def points_in_front(rng, cam, n=200, spread=1.0):
    return rng.normal(scale=spread, size=(n, 3))


# ---- projection --------------------------------------------------------------------------------
@pytest.mark.parametrize("n_dist", [0, 4, 5, 8, 12])
def test_project_matches_opencv(n_dist):
    rng = np.random.default_rng(10 + n_dist)
    for _ in range(5):
        cam = random_camera(rng, fx=rng.uniform(400, 1500), fy=rng.uniform(400, 1500), n_dist=n_dist)
        pts = points_in_front(rng, cam)
        ref, _ = cv2.projectPoints(pts, cam.rvec, cam.t, cam.K, cam.dist if n_dist else None)
        ours = cam.project(pts)
        assert np.abs(ours - ref.reshape(-1, 2)).max() < 1e-6


def test_project_batch_shape_and_depth():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, n_dist=5)
    pts = rng.normal(size=(7, 11, 3))
    uv, depth = cam.project_with_depth(pts)
    assert uv.shape == (7, 11, 2) and depth.shape == (7, 11)
    flat = cam.project(pts.reshape(-1, 3)).reshape(7, 11, 2)
    np.testing.assert_allclose(uv, flat, atol=0, rtol=0)
    np.testing.assert_allclose(depth, (pts @ cam.R.T + cam.t)[..., 2], atol=1e-12)
    # the centre projects on the principal axis at depth zero; a point 2 m along the axis at the principal point
    axis_point = cam.center + 2.0 * cam.R[2]
    uv0, d0 = cam.project_with_depth(axis_point)
    np.testing.assert_allclose(uv0, cam.K[:2, 2], atol=1e-9)
    assert abs(d0 - 2.0) < 1e-12


def test_center_and_projection_matrix():
    rng = np.random.default_rng(2)
    cam = random_camera(rng)
    np.testing.assert_allclose(cam.R @ cam.center + cam.t, 0, atol=1e-12)
    pts = rng.normal(size=(20, 3))
    h = np.hstack([pts, np.ones((20, 1))]) @ cam.projection_matrix.T
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], cam.project(pts), atol=1e-9)


def test_rodrigues_matches_opencv():
    rng = np.random.default_rng(3)
    for _ in range(50):
        rv = rng.normal(size=3)
        np.testing.assert_allclose(rodrigues_to_matrix(rv), cv2.Rodrigues(rv)[0], atol=1e-12)
        np.testing.assert_allclose(rodrigues_to_matrix(matrix_to_rodrigues(rodrigues_to_matrix(rv))),
                                   rodrigues_to_matrix(rv), atol=1e-10)


# ---- scaled ------------------------------------------------------------------------------------
def test_scaled_matches_resized_image_geometry():
    """A point on pixel (u, v) of the full image lands on ((u+.5)*s-.5, (v+.5)*s-.5) in the resized one."""
    rng = np.random.default_rng(4)
    cam = random_camera(rng, width=640, height=480, n_dist=5)
    half = cam.scaled(0.5)
    assert (half.width, half.height) == (320, 240)
    pts = points_in_front(rng, cam)
    full = cam.project(pts)
    np.testing.assert_allclose(half.project(pts), (full + 0.5) * 0.5 - 0.5, atol=1e-9)
    # rounding: the per-axis ratio actually used is new/old size
    odd = Camera("odd", cam.K, cam.dist, cam.R, cam.t, 641, 479).scaled(1 / 3)
    assert (odd.width, odd.height) == (214, 160)
    sx, sy = 214 / 641, 160 / 479
    exp = np.stack([(full[:, 0] + 0.5) * sx - 0.5, (full[:, 1] + 0.5) * sy - 0.5], axis=-1)
    np.testing.assert_allclose(odd.project(pts), exp, atol=1e-9)
    with pytest.raises(CameraError, match="positive"):
        cam.scaled(0)


def test_scaled_against_cv2_resize():
    """Render a small dot, resize with INTER_AREA, compare its centroid with the scaled camera's projection."""
    K = np.array([[500.0, 0, 199.3], [0, 500.0, 151.7], [0, 0, 1]])
    cam = Camera("c", K, [], np.eye(3), [0, 0, 0], 400, 300)
    p = np.array([0.11, -0.07, 1.0])
    u, v = cam.project(p)
    yy, xx = np.mgrid[0:300, 0:400]
    img = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 6.0 ** 2))
    small = cv2.resize(img, (100, 75), interpolation=cv2.INTER_AREA)
    ys, xs = np.mgrid[0:75, 0:100]
    centroid = np.array([(small * xs).sum(), (small * ys).sum()]) / small.sum()
    np.testing.assert_allclose(cam.scaled(0.25).project(p), centroid, atol=0.02)
    # the naive c*s would be off by 0.375 px here
    assert np.abs(cam.K[:2, 2] * 0.25 + (p[:2] * 125) - centroid).max() > 0.3


# ---- undistort ---------------------------------------------------------------------------------
@pytest.mark.parametrize("n_dist", [4, 5, 8])
def test_undistort_inverts_distortion(n_dist):
    rng = np.random.default_rng(5 + n_dist)
    cam = random_camera(rng, n_dist=n_dist, dist_scale=0.03)
    pts = rng.normal(scale=0.5, size=(100, 3))
    ideal = cam.without_distortion().project(pts)
    np.testing.assert_allclose(cam.undistort_points(cam.project(pts)), ideal, atol=1e-4)


# ---- validation --------------------------------------------------------------------------------
def test_bad_cameras_raise_clear_errors():
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    with pytest.raises(CameraError, match="cam_x.*3x3"):
        Camera("cam_x", K[:, :2], [], np.eye(3), [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="positive"):
        Camera("c", np.diag([-800.0, 800, 1]), [], np.eye(3), [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="orthonormal"):
        Camera("c", K, [], np.eye(3) * 1.1, [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="reflection"):
        Camera("c", K, [], np.diag([1.0, 1, -1]), [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="3 distortion"):
        Camera("c", K, [0.1, 0.2, 0.3], np.eye(3), [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="image size"):
        Camera("c", K, [], np.eye(3), [0, 0, 1], 0, 480)


# ---- Blender conversion (bpy-free part) ----------------------------------------------------------
CASES = [  # (width, height, fx, fy)
    (640, 480, 800.0, 800.0),
    (480, 640, 700.0, 700.0),
    (640, 480, 900.0, 780.0),
    (640, 480, 760.0, 910.0),
    (480, 640, 900.0, 780.0),
    (480, 640, 760.0, 910.0),
    (1920, 1080, 1400.0, 1400.0),
]


@pytest.mark.parametrize("fit", ["AUTO", "HORIZONTAL", "VERTICAL"])
@pytest.mark.parametrize("case", CASES)
def test_blender_params_round_trip(case, fit):
    rng = np.random.default_rng(hash((case, fit)) % 2 ** 32)
    W, H, fx, fy = case
    cam = random_camera(rng, W, H, fx, fy)
    back = camera_from_blender(camera_to_blender(cam, sensor_fit=fit))
    np.testing.assert_allclose(back.K, cam.K, atol=1e-9)
    np.testing.assert_allclose(back.R, cam.R, atol=1e-12)
    np.testing.assert_allclose(back.t, cam.t, atol=1e-12)
    assert (back.width, back.height) == (W, H)


def test_blender_params_known_values():
    """Square pixels, AUTO fit: lens = fx*36/max(W,H), shift from the documented closed form."""
    K = np.array([[1000.0, 0, 900.0], [0, 1000.0, 560.0], [0, 0, 1]])
    cam = Camera("c", K, [], np.eye(3), [0.0, 0.0, 3.0], 1920, 1080)
    p = camera_to_blender(cam)
    assert p.lens == pytest.approx(1000 * 36 / 1920)
    assert p.shift_x == pytest.approx((960 - 900.5) / 1920)
    assert p.shift_y == pytest.approx((560.5 - 540) / 1920)
    assert (p.pixel_aspect_x, p.pixel_aspect_y) == (1.0, 1.0)
    # OpenCV camera at identity looks along world +Z with +y down: Blender's camera -Z is world +Z.
    np.testing.assert_allclose(p.matrix_world[:3, 3], [0, 0, -3.0])
    np.testing.assert_allclose(p.matrix_world[:3, :3] @ [0, 0, -1.0], [0, 0, 1.0])
    np.testing.assert_allclose(p.matrix_world[:3, :3] @ [0, 1.0, 0], [0, -1.0, 0])


def test_blender_rejects_skew_and_bad_fit():
    K = np.array([[800.0, 3.0, 320], [0, 800, 240], [0, 0, 1]])
    cam = Camera("c", K, [], np.eye(3), [0, 0, 1], 640, 480)
    with pytest.raises(CameraError, match="skew"):
        camera_to_blender(cam)
    cam.K[0, 1] = 0
    with pytest.raises(CameraError, match="sensor_fit"):
        camera_to_blender(cam, sensor_fit="DIAGONAL")


# ---- against real Blender ----------------------------------------------------------------------
def _blender_pixels(bpy, scene, cam_obj, pts, W, H):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    out = []
    for p in pts:
        ndc = world_to_camera_view(scene, cam_obj, Vector(p.tolist()))
        out.append((ndc.x * W - 0.5, (1.0 - ndc.y) * H - 0.5))
    return np.array(out)


@pytest.mark.bpy
@pytest.mark.parametrize("fit", ["AUTO", "HORIZONTAL", "VERTICAL"])
def test_blender_projection_matches_core(bpy_module, fit):
    from markerless_mocap.addon.camera_bridge import camera_from_object, create_blender_camera

    bpy = bpy_module
    scene = bpy.context.scene
    rng = np.random.default_rng({"AUTO": 0, "HORIZONTAL": 1, "VERTICAL": 2}[fit])
    for W, H, fx, fy in CASES:
        cam = random_camera(rng, W, H, fx, fy, name=f"c{W}x{H}")
        obj = create_blender_camera(scene, cam, sensor_fit=fit)
        bpy.context.view_layer.update()
        pts = points_in_front(rng, cam)
        assert np.all(cam.project_with_depth(pts)[1] > 0.5)
        got = _blender_pixels(bpy, scene, obj, pts, W, H)
        err = np.abs(got - cam.project(pts)).max()
        assert err < 0.01, f"{W}x{H} fx={fx} fy={fy} fit={fit}: {err:.4g} px"
        back = camera_from_object(obj, scene)
        np.testing.assert_allclose(back.K, cam.K, atol=1e-4)
        np.testing.assert_allclose(back.R, cam.R, atol=1e-6)
        # Blender stores matrix_world in float32: the centre is stored directly (~2.4e-7 m at 5 m) but
        # t = -R C also carries R's float32 error times the ~5 m distance (measured max 1.3e-6 m over
        # 200 cameras), hence 2e-6 for t.
        np.testing.assert_allclose(back.center, cam.center, atol=1e-6)
        np.testing.assert_allclose(back.t, cam.t, atol=2e-6)
        assert (back.width, back.height) == (W, H)


@pytest.mark.bpy
def test_blender_negative_control_shift_sign(bpy_module):
    """Flipping shift_x must move projected points by W - 2cx - 1 px: the test can see a wrong sign."""
    from markerless_mocap.addon.camera_bridge import create_blender_camera

    bpy = bpy_module
    scene = bpy.context.scene
    rng = np.random.default_rng(7)
    cam = random_camera(rng, 640, 480, 800, 800)
    obj = create_blender_camera(scene, cam, sensor_fit="HORIZONTAL")
    obj.data.shift_x = -obj.data.shift_x
    bpy.context.view_layer.update()
    pts = points_in_front(rng, cam, n=20)
    d = _blender_pixels(bpy, scene, obj, pts, 640, 480) - cam.project(pts)
    np.testing.assert_allclose(d[:, 0], 640 - 2 * cam.K[0, 2] - 1, atol=0.01)


@pytest.mark.bpy
def test_blender_cameras_of_different_sizes_share_the_scene(bpy_module):
    """Render size is per scene: each camera keeps its own and activate_camera applies it."""
    from markerless_mocap.addon.camera_bridge import activate_camera, camera_from_object, create_blender_camera

    bpy = bpy_module
    scene = bpy.context.scene
    rng = np.random.default_rng(11)
    land = random_camera(rng, 640, 480, 900, 780, name="land")
    port = random_camera(rng, 480, 640, 700, 700, name="port")
    obj_land = create_blender_camera(scene, land)
    obj_port = create_blender_camera(scene, port)
    assert (scene.render.resolution_x, scene.render.resolution_y) == (480, 640)  # the last one created
    activate_camera(scene, obj_land)
    assert scene.camera == obj_land
    assert (scene.render.resolution_x, scene.render.resolution_y) == (640, 480)
    assert scene.render.pixel_aspect_y / scene.render.pixel_aspect_x == pytest.approx(900 / 780, rel=1e-6)
    bpy.context.view_layer.update()
    pts = points_in_front(rng, land, n=50)
    assert np.abs(_blender_pixels(bpy, scene, obj_land, pts, 640, 480) - land.project(pts)).max() < 0.01
    # each camera reads back with its own size whatever the scene is set to
    np.testing.assert_allclose(camera_from_object(obj_port, scene).K, port.K, atol=1e-4)
    assert camera_from_object(obj_port, scene).size == (480, 640)
    mesh_obj = bpy.data.objects.new("empty", None)
    with pytest.raises(ValueError, match="not a camera"):
        camera_from_object(mesh_obj, scene)


@pytest.mark.bpy
@pytest.mark.parametrize("fit,res,aspect", [("AUTO", (1280, 720), (1.0, 1.0)), ("AUTO", (720, 1280), (1.0, 1.3)),
                                            ("VERTICAL", (800, 600), (1.2, 1.0)),
                                            ("HORIZONTAL", (600, 800), (1.0, 1.0))])
def test_blender_native_camera_reads_back(bpy_module, fit, res, aspect):
    """A camera set up by hand in Blender (no custom properties): the inverse formula alone must agree
    with world_to_camera_view."""
    from mathutils import Euler, Vector

    from markerless_mocap.addon.camera_bridge import camera_from_object

    bpy = bpy_module
    scene = bpy.context.scene
    data = bpy.data.cameras.new("native")
    data.lens, data.sensor_width, data.sensor_height, data.sensor_fit = 42.0, 36.0, 20.0, fit
    data.shift_x, data.shift_y = 0.07, -0.04
    obj = bpy.data.objects.new("native", data)
    scene.collection.objects.link(obj)
    obj.location = Vector((4.0, -5.0, 1.7))
    obj.rotation_euler = Euler((1.3, 0.1, 0.7))
    scene.render.resolution_x, scene.render.resolution_y = res
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = aspect
    bpy.context.view_layer.update()
    cam = camera_from_object(obj, scene)
    assert cam.size == res
    rng = np.random.default_rng(0)
    # points inside the view frustum, 3-8 m in front of the camera
    pix = rng.uniform([0, 0], res, size=(100, 2))
    depth = rng.uniform(3, 8, size=100)
    rays = np.linalg.solve(cam.K, np.hstack([pix, np.ones((100, 1))]).T).T * depth[:, None]
    pts = (rays - cam.t) @ cam.R  # camera -> world
    got = _blender_pixels(bpy, scene, obj, pts, *res)
    np.testing.assert_allclose(got, cam.project(pts), atol=0.01)
    np.testing.assert_allclose(got, pix, atol=0.01)


def test_skew_and_normalised_distortion_against_references():
    """Skew (cv2.projectPoints ignores it) against K @ [x_d, y_d, 1]; distort_normalized against cv2 with K = I."""
    rng = np.random.default_rng(12)
    cam = random_camera(rng, n_dist=8)
    cam.K[0, 1] = 2.5
    pts = rng.normal(size=(50, 3))
    pc = pts @ cam.R.T + cam.t
    xy, _ = cv2.projectPoints(pc, np.zeros(3), np.zeros(3), np.eye(3), cam.dist)
    xy = xy.reshape(-1, 2)
    np.testing.assert_allclose(cam.distort_normalized(pc[:, :2] / pc[:, 2:]), xy, atol=1e-12)
    ref = np.hstack([xy, np.ones((50, 1))]) @ cam.K.T
    np.testing.assert_allclose(cam.project(pts), ref[:, :2], atol=1e-9)
    uv, depth = cam.project_with_depth(pts[0])
    assert uv.shape == (2,) and depth.shape == ()
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        cam.project(np.zeros((4, 2)))
