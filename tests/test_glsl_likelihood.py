"""The GLSL likelihood (Blender's gpu module; Mesa's llvmpipe on CPU machines) against the NumPy reference.

The GPU is probed in a subprocess first (a missing EGL/Mesa library would abort pytest itself); the tests
skip only when that probe fails, with its reason.
"""
import numpy as np
import pytest

from markerless_mocap.core.energy import likelihood as lk
from markerless_mocap.core import render
from markerless_mocap.core.render import reference

from test_render import look_at, random_blob_targets

pytestmark = pytest.mark.bpy


@pytest.fixture(scope="module")
def gpu_backend():
    pytest.importorskip("bpy")
    from markerless_mocap.operators import backend_choice

    probe = backend_choice.probe_gpu()
    if not probe.get("ok"):
        pytest.skip(f"no usable GPU context here: {probe.get('error')}")
    choice = backend_choice.choose_backend("gpu")
    assert choice.used == "gpu" and render.resolve_backend("gpu") == "gpu"
    return probe


@pytest.fixture(scope="module")
def subject():
    bpy = pytest.importorskip("bpy")
    from rig_helpers import load_subject, subject_blend_path

    if not subject_blend_path().is_file():
        pytest.skip(f"no sample subject at {subject_blend_path()} (set MOCAP_TEST_SUBJECT)")
    from markerless_mocap.addon.scene_bridge import body_from_blender
    from markerless_mocap.core.body.proxy import make_proxy

    arm, mesh = load_subject(bpy)
    body = body_from_blender(arm, mesh)
    return body, make_proxy(body, 2000)


def _cameras(body, sizes=((320, 240),) * 4):
    """Four views around the subject; the second with OpenCV lens distortion, the last of another size."""
    centre = body.default_pose()[:3]
    dists = [(), (-0.12, 0.05, 0.002, -0.001, 0.01), (), ()]
    return [look_at(f"c{i}", [3.5 * np.cos(a), 3.5 * np.sin(a), 1.2], centre, 275 * w / 320, w, h, dists[i])
            for i, (a, (w, h)) in enumerate(zip(np.deg2rad([20, 110, 200, 290]), sizes))]


def _random_poses(body, rng, n):
    x0 = body.default_pose()
    lo = np.where(np.isfinite(body.lower), body.lower, -0.3)
    hi = np.where(np.isfinite(body.upper), body.upper, 0.3)
    poses = np.tile(x0, (n, 1))
    poses[:, 6:] = rng.uniform(lo[6:], hi[6:], (n, body.n_dof - 6)) * 0.5
    poses[:, :3] += rng.normal(0, 0.1, (n, 3))
    poses[:, 3:6] += rng.normal(0, 0.2, (n, 3))
    return poses


@pytest.mark.parametrize("cull", [0, -1])
def test_glsl_statistics_equal_the_reference_on_random_poses(gpu_backend, subject, cull):
    body, proxy = subject
    cams = _cameras(body, sizes=((320, 240), (320, 240), (320, 240), (288, 216)))
    rng = np.random.default_rng(7)
    targets = random_blob_targets(cams, rng)
    poses = _random_poses(body, rng, 10)
    labels = (proxy.face_part + 1).astype(np.int16)
    s_gpu, _ = render.measure_poses(body, proxy, poses, cams, proxy.faces, labels, targets, need_chamfer=False,
                                    cull=cull, backend="gpu")
    uv, z = render.project_views(proxy.deform(body, poses), cams)
    s_ref, _ = reference.statistics(uv, z, proxy.faces, labels, targets, False, 0, cull)
    assert s_ref[..., render.TEMPLATE].min() > 300  # every pose is seen in every view
    for column in (render.TEMPLATE, render.OVERLAP, render.BOUNDARY, render.BOUNDARY_OFF, render.SUM_DI,
                   render.SUM_EDGE_DT):
        ref, got = s_ref[..., column], s_gpu[..., column]
        # pixel centres exactly on a triangle edge may go the other way (the top-left rule's y direction)
        assert np.all(np.abs(got - ref) <= 0.01 * np.maximum(ref, 100)), (column, np.abs(got - ref).max())


def test_batches_larger_than_one_atlas_are_drawn_in_chunks(gpu_backend, subject, monkeypatch):
    """A batch that needs several atlases (here 4 tiles each) gives what one atlas gives."""
    from markerless_mocap.addon import gpu_likelihood

    body, proxy = subject
    cams = _cameras(body)
    rng = np.random.default_rng(5)
    targets = random_blob_targets(cams, rng)
    poses = _random_poses(body, rng, 5)
    labels = (proxy.face_part + 1).astype(np.int16)
    whole, _ = render.measure_poses(body, proxy, poses, cams, proxy.faces, labels, targets, need_chamfer=False,
                                    backend="gpu")
    monkeypatch.setattr(gpu_likelihood, "_side", {"atlas_side": 700})  # 2 x 2 tiles of 320x240
    chunked, _ = render.measure_poses(body, proxy, poses, cams, proxy.faces, labels, targets, need_chamfer=False,
                                      backend="gpu")
    assert whole[..., render.TEMPLATE].min() > 300
    # the same pixels, up to a pixel centre on a triangle edge: window coordinates round differently per tile
    assert np.allclose(whole, chunked, rtol=1e-3, atol=3)


def test_glsl_energies_equal_the_reference_within_one_percent(gpu_backend, subject):
    """EnergyModel on the GLSL path (called repeatedly: GPU objects are kept between calls) against the
    NumPy reference, silhouette, edge and Chamfer edge terms; a likelihood with a Chamfer silhouette
    falls back to the CPU path for that statistic and still agrees."""
    import warnings

    from markerless_mocap.operators.cmd_bench import synthetic_features

    body, proxy = subject
    cams = _cameras(body)
    rng = np.random.default_rng(11)
    observed = _random_poses(body, rng, 1)[0]
    weights = lk.LikelihoodWeights(silh=30.0, edge=2.0, edge_ch=1.0, silh_ch=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        models = {b: lk.EnergyModel(body, proxy, cams, weights, scale=1.0, backend=b) for b in ("gpu", "numpy")}
    feats = synthetic_features(models["numpy"], observed)
    for m in models.values():
        m.set_reference_pose(lk.default_pose_at(body, observed))
        m.set_frame(feats)
    poses = _random_poses(body, rng, 12)
    ref = models["numpy"].terms(poses)
    for _ in range(2):
        got = models["gpu"].terms(poses)
        for name in ("silh", "edge", "edge_ch", "silh_ch"):
            assert np.allclose(got[name], ref[name], rtol=0.01, atol=1e-9), (name, got[name], ref[name])
    assert np.allclose(models["gpu"](poses), models["numpy"](poses), rtol=0.01)


def test_gpu_asked_for_without_a_gpu_is_one_line_naming_the_fix(monkeypatch):
    from markerless_mocap.operators import backend_choice

    monkeypatch.setattr(backend_choice, "_probe_result", {"ok": False, "error": "libEGL.so.1: cannot open"})
    with pytest.raises(render.BackendUnavailableError) as err:
        backend_choice.choose_backend("gpu")
    message = str(err.value)
    assert "\n" not in message and "libEGL" in message and "apt-get install" in message and "fast" in message
    auto = backend_choice.choose_backend("auto")
    assert auto.used in ("fast", "numpy") and "libEGL" in auto.reason


def test_auto_does_not_pick_a_software_rasteriser(monkeypatch):
    from markerless_mocap.operators import backend_choice

    monkeypatch.setattr(backend_choice, "_probe_result", {"ok": True, "renderer": "llvmpipe (LLVM 15.0.6)"})
    choice = backend_choice.choose_backend("auto")
    assert choice.used == render.resolve_backend("auto") and "software" in choice.reason
    assert choice.to_dict()["gpu_renderer"].startswith("llvmpipe")
    assert choice.summary == f"{choice.used} (the GPU is llvmpipe, software)"  # what the Track panel shows


def test_tile_boxes_hold_every_template_pixel(subject):
    """The reduction scans only tile_boxes' pixels: every pixel the reference rasterises must be inside."""
    from markerless_mocap.core.render import glsl

    body, proxy = subject
    cams = _cameras(body)
    cams[1] = cams[1].without_distortion()  # a distorted view gets the whole image; test the bound itself
    rng = np.random.default_rng(3)
    poses = _random_poses(body, rng, 8)
    boxes = glsl.tile_boxes(body.skinning_matrices(poses), body.skeleton.armature_matrix,
                            *glsl.bone_spheres(proxy.vertices, proxy.weights, proxy.unweighted), cams,
                            [c.width for c in cams], [c.height for c in cams])
    uv, z = render.project_views(proxy.deform(body, poses), cams)
    labels = (proxy.face_part + 1).astype(np.int16)
    for p in range(len(poses)):
        for c, cam in enumerate(cams):
            ys, xs = np.nonzero(reference.rasterize(uv[p, c], z[p, c], proxy.faces, labels, cam.width, cam.height))
            x0, y0, x1, y1 = boxes[p, c]
            assert xs.size and xs.min() >= x0 and xs.max() <= x1 and ys.min() >= y0 and ys.max() <= y1
            assert (x1 - x0 + 1) * (y1 - y0 + 1) < 0.6 * cam.width * cam.height  # and it does cut the work
