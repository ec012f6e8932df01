"""The GLSL likelihood on Blender's `gpu` module: compiles core/render/glsl.py's shaders and runs them.

Where the GPU is reachable:
* in the interactive UI, on the main thread: the gpu module works directly;
* in background mode (`python -m markerless_mocap`, `blender -b`) only inside a RenderEngine with
  `bl_use_gpu_context`: each batch is handed to `bpy.ops.render.render()` on a small private scene whose
  engine runs it (about 3 ms of overhead per batch on llvmpipe).

`install()` registers the path with core.render as backend "gpu" (core never imports bpy).
Main thread only, like everything that touches bpy.
"""
from __future__ import annotations

import numpy as np

from ..core import render
from ..core.render import glsl

ENGINE_ID = "MOCAP_GLSL_LIKELIHOOD"
SCENE_NAME = ".markerless_mocap GLSL likelihood"


class GpuUnavailableError(RuntimeError):
    """The GPU path cannot run in this process (no OpenGL context, a driver error)."""


# ---------------------------------------------------------------------------------------- GPU context
_job = {}


def _engine_class():
    import bpy

    class GlslLikelihoodEngine(bpy.types.RenderEngine):
        """Runs the pending GPU job inside Blender's render GPU context (background mode)."""
        bl_idname = ENGINE_ID
        bl_label = "Markerless Mocap GLSL likelihood"
        bl_use_gpu_context = True

        def render(self, depsgraph):
            fn = _job.pop("fn", None)
            if fn is None:
                return
            try:
                _job["result"] = fn()
            except BaseException as exc:  # noqa: BLE001  (handed back to the caller, raised there)
                _job["error"] = exc

    return GlslLikelihoodEngine


_engine = None


def _private_scene():
    import bpy

    global _engine
    if _engine is None:
        _engine = _engine_class()
        bpy.utils.register_class(_engine)
    scene = bpy.data.scenes.get(SCENE_NAME)
    if scene is None:
        scene = bpy.data.scenes.new(SCENE_NAME)
        scene.render.engine = ENGINE_ID
        scene.render.resolution_x = scene.render.resolution_y = 4
        scene.render.resolution_percentage = 100
        # Rendering needs a camera, although the engine never looks through it.
        camera = bpy.data.objects.new(SCENE_NAME, bpy.data.cameras.new(SCENE_NAME))
        scene.collection.objects.link(camera)
        scene.camera = camera
    return scene


def run_in_gpu_context(fn):
    """fn() where the gpu module can draw: directly in the UI, inside the render engine in background."""
    import threading

    import bpy

    if threading.current_thread() is not threading.main_thread():
        raise GpuUnavailableError("the GPU likelihood runs only on Blender's main thread; track in the "
                                  "foreground or choose backend fast")
    if not bpy.app.background:
        return fn()
    scene = _private_scene()
    _job.clear()
    _job["fn"] = fn
    try:
        bpy.ops.render.render(scene=scene.name)
    except RuntimeError as exc:
        raise GpuUnavailableError(f"Blender could not start its render GPU context ({exc})") from exc
    if "error" in _job:
        raise _job.pop("error")
    if "result" not in _job:
        raise GpuUnavailableError("Blender's render engine did not run the GPU job (no GPU context)")
    return _job.pop("result")


def release():
    """Free the kept GPU objects (inside a GPU context), then remove the private scene (so it is not saved
    with the user's file) and the engine."""
    import bpy

    global _engine
    if _cache:
        try:
            run_in_gpu_context(_cache.clear)
        except GpuUnavailableError:
            _cache.clear()
    scene = bpy.data.scenes.get(SCENE_NAME)
    if scene is not None:
        camera = scene.camera
        bpy.data.scenes.remove(scene)
        if camera is not None:
            data = camera.data
            bpy.data.objects.remove(camera)
            bpy.data.cameras.remove(data)
    if _engine is not None:
        bpy.utils.unregister_class(_engine)
        _engine = None


def renderer():
    """(vendor, renderer, version) of the OpenGL implementation the gpu module draws with."""
    import gpu

    return run_in_gpu_context(lambda: (gpu.platform.vendor_get(), gpu.platform.renderer_get(),
                                       gpu.platform.version_get()))


def is_software(renderer_name):
    """A CPU rasteriser (Mesa's llvmpipe/softpipe, swrast): the numba path is faster there."""
    name = renderer_name.lower()
    return any(s in name for s in ("llvmpipe", "softpipe", "swrast", "software"))


# ---------------------------------------------------------------------------------------- shaders
def _float_buffer(array):
    """A gpu.types.Buffer holding float32 `array` (filled through a NumPy view: no Python loop)."""
    import gpu

    a = np.ascontiguousarray(array, dtype=np.float32).reshape(-1)
    buf = gpu.types.Buffer("FLOAT", a.size)
    np.asarray(buf)[:] = a
    return buf


def _texture(array):
    """(rows, columns, 4) float32 -> an RGBA32F texture of columns x rows texels."""
    import gpu

    rows, cols = array.shape[:2]
    return gpu.types.GPUTexture((cols, rows), format="RGBA32F", data=_float_buffer(array))


def _draw_shader(slots):
    import gpu

    iface = gpu.types.GPUStageInterfaceInfo("mocap_draw_iface")
    iface.flat("FLOAT", "label_v")
    iface.flat("VEC4", "tile_box")
    iface.smooth("FLOAT", "near")
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC3", "rest")
    info.vertex_in(1, "FLOAT", "label")
    for k in range(slots):
        info.vertex_in(2 + 2 * k, "VEC4", f"bone{k}")
        info.vertex_in(3 + 2 * k, "VEC4", f"weight{k}")
    info.vertex_out(iface)
    info.sampler(0, "FLOAT_2D", "bones")
    info.sampler(1, "FLOAT_2D", "cameras")
    info.sampler(2, "FLOAT_2D", "sizes")
    for kind, name in (("INT", "first_tile"), ("INT", "n_views"), ("INT", "tiles_per_row"), ("INT", "tile_w"),
                       ("INT", "tile_h"), ("INT", "cull"), ("VEC2", "atlas_size"), ("FLOAT", "near_z")):
        info.push_constant(kind, name)
    info.fragment_out(0, "VEC4", "label_out")
    info.vertex_source(glsl.draw_vertex_source(slots))
    info.fragment_source(glsl.DRAW_FRAGMENT_SOURCE)
    return gpu.shader.create_from_info(info)


def _reduce_shader(fragment_source, samplers, constants):
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC2", "pos")
    for slot, name in enumerate(samplers):
        info.sampler(slot, "FLOAT_2D", name)
    for kind, name in constants:
        info.push_constant(kind, name)
    info.fragment_out(0, "VEC4", "counts_out")
    info.fragment_out(1, "VEC4", "sums_out")
    info.vertex_source(glsl.FULLSCREEN_VERTEX_SOURCE)
    info.fragment_source(fragment_source)
    return gpu.shader.create_from_info(info)


# ---------------------------------------------------------------------------------------- the path
class GlslStatistics:
    """Likelihood statistics of many poses in every view, rendered and reduced in GLSL.

    Shaders, the mesh batch, the render targets and the frame's observed images are made once and kept
    (they stay valid from one render-engine call to the next: checked by tests/test_glsl_likelihood.py,
    which calls it repeatedly)."""

    def __init__(self):
        self._mesh_key = None
        self._mesh = None
        self._targets_key = None
        self._targets = None

    def __call__(self, skin_matrices, armature_matrix, proxy_vertices, proxy_weights, unweighted, faces,
                 face_label, cameras, targets, cull=0):
        """(P,C,N_STATS) statistics; the columns the GLSL path does not compute (SUM_DT) are 0."""
        bones = glsl.pack_bones(skin_matrices, armature_matrix)
        mesh_key = [np.asarray(a) for a in (proxy_vertices, proxy_weights, faces, face_label)]
        if self._mesh_key is None or not all(a.shape == b.shape and np.array_equal(a, b)
                                             for a, b in zip(mesh_key, self._mesh_key)):
            self._mesh = glsl.pack_mesh(proxy_vertices, proxy_weights, unweighted, faces, face_label,
                                        proxy_weights.shape[1])
            self._spheres = glsl.bone_spheres(proxy_vertices, proxy_weights, unweighted)
            self._mesh_key = [a.copy() for a in mesh_key]
        boxes = glsl.pack_boxes(glsl.tile_boxes(skin_matrices, armature_matrix, *self._spheres, cameras,
                                                targets.widths, targets.heights))
        if targets is not self._targets_key:
            self._targets = glsl.pack_targets(targets)
            self._targets_key = targets
        sizes = np.zeros((1, len(cameras), 4), np.float32)
        sizes[0, :, 0] = targets.widths
        sizes[0, :, 1] = targets.heights
        P, C = len(bones), len(cameras)
        H, W = targets.silhouette.shape[1:]
        job = (bones, glsl.pack_cameras(cameras), sizes, boxes, self._targets, self._mesh, P, C, W, H, int(cull))
        readback = run_in_gpu_context(lambda: _run(*job))
        return glsl.unpack_statistics(readback, P, C, render.N_STATS)


def _atlas_side():
    """Inside a GPU context: the atlas side for this GPU (glsl.ATLAS_SIDE_GPU on hardware, within its limit)."""
    import gpu

    if "atlas_side" not in _side:
        hardware = not is_software(gpu.platform.renderer_get())
        limit = gpu.capabilities.max_texture_size_get()
        _side["atlas_side"] = min(limit, glsl.ATLAS_SIDE_GPU if hardware else glsl.ATLAS_SIDE)
    return _side["atlas_side"]


_side = {}
_cache = {}  # GPU objects kept between calls: shaders, batches, render targets, the observed images


def _run(*job):
    """_passes with the GPU state it changes put back (in the UI, the next viewport draw expects it)."""
    import gpu

    saved = (gpu.state.viewport_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get(),
             gpu.state.blend_get())
    try:
        return _passes(*job)
    finally:
        gpu.state.viewport_set(*saved[0])
        gpu.state.depth_test_set(saved[1])
        gpu.state.depth_mask_set(saved[2])
        gpu.state.blend_set(saved[3])
        gpu.state.face_culling_set("NONE")


def _passes(bones, cameras, sizes, boxes, observed, mesh, P, C, W, H, cull):
    """Inside a GPU context: every pose-view in atlas chunks -> (P*C, 8) floats."""
    import gpu
    from gpu_extras.batch import batch_for_shader

    slots = sum(1 for k in mesh[0] if k.startswith("bone"))
    if _cache.get("slots") != slots:
        _cache.clear()
        _cache["slots"] = slots
        _cache["draw"] = _draw_shader(slots)
        _cache["rows"] = _reduce_shader(glsl.ROWS_FRAGMENT_SOURCE, ("labels", "observed", "sizes", "boxes"),
                                        (("INT", "first_tile"), ("INT", "n_views"), ("INT", "tiles_per_row"),
                                         ("INT", "tile_w"), ("INT", "tile_h")))
        _cache["tiles"] = _reduce_shader(glsl.TILES_FRAGMENT_SOURCE, ("row_counts", "row_sums"),
                                         (("INT", "n_rows"),))
    draw, rows, tiles = _cache["draw"], _cache["rows"], _cache["tiles"]
    if _cache.get("mesh") is not mesh:
        _cache["mesh"] = mesh
        attributes, indices = mesh
        _cache["mesh_batch"] = batch_for_shader(draw, "TRIS", attributes, indices=indices)
        quad = ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))
        _cache["rows_batch"] = batch_for_shader(rows, "TRIS", {"pos": quad})
        _cache["tiles_batch"] = batch_for_shader(tiles, "TRIS", {"pos": quad})
    mesh_batch, rows_batch, tiles_batch = _cache["mesh_batch"], _cache["rows_batch"], _cache["tiles_batch"]
    bone_tex, camera_tex, size_tex, box_tex = _texture(bones), _texture(cameras), _texture(sizes), _texture(boxes)
    if _cache.get("observed") is not observed:  # once per frame
        _cache["observed"] = observed
        _cache["observed_tex"] = _texture(observed)
    observed_tex = _cache["observed_tex"]

    n_tiles = P * C
    per_row, n_rows, per_atlas = glsl.atlas_layout(n_tiles, W, H, _atlas_side())
    atlas_w, atlas_h = per_row * W, n_rows * H
    key = (atlas_w, atlas_h, per_atlas, H)
    if _cache.get("targets_key") != key:
        labels = gpu.types.GPUTexture((atlas_w, atlas_h), format="R32F")
        depth = gpu.types.GPUTexture((atlas_w, atlas_h), format="DEPTH_COMPONENT32F")
        row_counts = gpu.types.GPUTexture((per_atlas, H), format="RGBA32F")
        row_sums = gpu.types.GPUTexture((per_atlas, H), format="RGBA32F")
        tile_counts = gpu.types.GPUTexture((per_atlas, 1), format="RGBA32F")
        tile_sums = gpu.types.GPUTexture((per_atlas, 1), format="RGBA32F")
        _cache["targets"] = (labels, depth, row_counts, row_sums, tile_counts, tile_sums)
        _cache["targets_key"] = key
    labels, depth, row_counts, row_sums, tile_counts, tile_sums = _cache["targets"]
    label_fb = gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=(labels,))
    rows_fb = gpu.types.GPUFrameBuffer(color_slots=(row_counts, row_sums))
    tiles_fb = gpu.types.GPUFrameBuffer(color_slots=(tile_counts, tile_sums))
    out = np.zeros((n_tiles, 8), np.float32)
    counts_buf = gpu.types.Buffer("FLOAT", per_atlas * 4)
    sums_buf = gpu.types.Buffer("FLOAT", per_atlas * 4)
    for first in range(0, n_tiles, per_atlas):
        n = min(per_atlas, n_tiles - first)
        with label_fb.bind():
            label_fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gpu.state.viewport_set(0, 0, atlas_w, atlas_h)
            gpu.state.depth_test_set("LESS")
            gpu.state.depth_mask_set(True)
            # Back-face culling in the rasteriser (half the triangles never set up); the fragment shader's
            # gl_FrontFacing test states the same rule.
            gpu.state.face_culling_set({0: "NONE", 1: "BACK", -1: "FRONT"}[cull])
            gpu.state.blend_set("NONE")
            draw.bind()
            draw.uniform_sampler("bones", bone_tex)
            draw.uniform_sampler("cameras", camera_tex)
            draw.uniform_sampler("sizes", size_tex)
            for name, value in (("first_tile", first), ("n_views", C), ("tiles_per_row", per_row), ("tile_w", W),
                                ("tile_h", H), ("cull", cull)):
                draw.uniform_int(name, value)
            draw.uniform_float("atlas_size", (float(atlas_w), float(atlas_h)))
            draw.uniform_float("near_z", glsl.Z_NEAR)
            mesh_batch.draw_instanced(draw, instance_start=0, instance_count=n)
            gpu.state.depth_test_set("NONE")
            gpu.state.depth_mask_set(False)
            gpu.state.face_culling_set("NONE")
        with rows_fb.bind():
            gpu.state.viewport_set(0, 0, n, H)
            rows.bind()
            rows.uniform_sampler("labels", labels)
            rows.uniform_sampler("observed", observed_tex)
            rows.uniform_sampler("sizes", size_tex)
            rows.uniform_sampler("boxes", box_tex)
            for name, value in (("first_tile", first), ("n_views", C), ("tiles_per_row", per_row), ("tile_w", W),
                                ("tile_h", H)):
                rows.uniform_int(name, value)
            rows_batch.draw(rows)
        with tiles_fb.bind():
            gpu.state.viewport_set(0, 0, n, 1)
            tiles.bind()
            tiles.uniform_sampler("row_counts", row_counts)
            tiles.uniform_sampler("row_sums", row_sums)
            tiles.uniform_int("n_rows", H)
            tiles_batch.draw(tiles)
            tiles_fb.read_color(0, 0, n, 1, 4, 0, "FLOAT", data=counts_buf)
            tiles_fb.read_color(0, 0, n, 1, 4, 1, "FLOAT", data=sums_buf)
        out[first:first + n, :4] = np.asarray(counts_buf)[:n * 4].reshape(n, 4)
        out[first:first + n, 4:] = np.asarray(sums_buf)[:n * 4].reshape(n, 4)
    return out


_instance = None


def measure_poses(body, proxy, poses, cameras, faces, face_label, targets, cull=0):
    """core.render's "gpu" backend entry: poses (P,D) -> (P,C,N_STATS) statistics."""
    global _instance
    if _instance is None:
        _instance = GlslStatistics()
    skin = body.skinning_matrices(poses)
    return _instance(skin, body.skeleton.armature_matrix, proxy.vertices, proxy.weights, proxy.unweighted, faces,
                     face_label, cameras, targets, cull)


def install():
    """Make backend "gpu" available to core.render in this process; its GPU objects are freed at exit."""
    import atexit

    if not _installed:
        atexit.register(_release_at_exit)
        _installed.append(True)
    render.register_gpu(measure_poses)


_installed = []


def _release_at_exit():
    try:
        release()
    except Exception:  # noqa: BLE001  (Blender may already be shutting its data down: nothing left to free)
        pass
