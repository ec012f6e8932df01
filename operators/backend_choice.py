"""Which likelihood backend a run uses: `auto | numpy | fast | gpu` -> one that works here, and why.

The GPU path is probed in a subprocess first: a missing EGL or Mesa library aborts the whole process
(not a Python exception), so it must not happen in the process that tracks. `auto` takes the GPU only
when the probe finds a hardware GPU: on a software rasteriser (Mesa's llvmpipe, what these CPU machines
have) the GLSL path runs on the same cores as the numba path and is far slower (docs/speed.md, the GPU path).
"""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass

PROBE_TIMEOUT_S = 120.0
# The probe: a RenderEngine with a GPU context draws one triangle with a GPUShaderCreateInfo shader into an
# offscreen framebuffer and reads it back; prints one JSON line. Self-contained: it must not need the add-on.
_PROBE_SCRIPT = r'''
import json, sys
import bpy, gpu
from gpu_extras.batch import batch_for_shader
out = {}
class ProbeEngine(bpy.types.RenderEngine):
    bl_idname = "MOCAP_GPU_PROBE"
    bl_label = "probe"
    bl_use_gpu_context = True
    def render(self, depsgraph):
        try:
            info = gpu.types.GPUShaderCreateInfo()
            info.vertex_in(0, "VEC2", "pos")
            info.fragment_out(0, "VEC4", "color")
            info.vertex_source("void main() { gl_Position = vec4(pos, 0.0, 1.0); }")
            info.fragment_source("void main() { color = vec4(1.0, 0.0, 0.0, 1.0); }")
            shader = gpu.shader.create_from_info(info)
            batch = batch_for_shader(shader, "TRIS", {"pos": ((-1, -1), (1, -1), (-1, 1))})
            tex = gpu.types.GPUTexture((16, 16), format="R32F")
            fb = gpu.types.GPUFrameBuffer(color_slots=(tex,))
            with fb.bind():
                fb.clear(color=(0.0, 0.0, 0.0, 0.0))
                gpu.state.viewport_set(0, 0, 16, 16)
                batch.draw(shader)
                buf = gpu.types.Buffer("FLOAT", 256)
                fb.read_color(0, 0, 16, 16, 1, 0, "FLOAT", data=buf)
            lit = sum(1 for v in buf if v > 0.5)
            out.update(ok=100 <= lit <= 156, pixels=lit, renderer=gpu.platform.renderer_get(),
                       vendor=gpu.platform.vendor_get(), version=gpu.platform.version_get())
        except Exception as exc:
            out.update(ok=False, error=f"{type(exc).__name__}: {exc}")
bpy.utils.register_class(ProbeEngine)
scene = bpy.context.scene
scene.render.engine = "MOCAP_GPU_PROBE"
scene.render.resolution_x = scene.render.resolution_y = 4
if scene.camera is None:
    cam = bpy.data.objects.new("probe", bpy.data.cameras.new("probe"))
    scene.collection.objects.link(cam)
    scene.camera = cam
try:
    bpy.ops.render.render()
except Exception as exc:
    out.update(ok=False, error=f"{type(exc).__name__}: {exc}")
if not out:
    out.update(ok=False, error="the render engine did not run (no GPU context)")
print("MOCAP_GPU_PROBE " + json.dumps(out), flush=True)
'''
FIX = ("install an OpenGL 4.3+ driver (on Linux without a GPU: apt-get install libegl1 libgl1-mesa-dri, "
       "Mesa's llvmpipe), or choose backend fast")


@dataclass
class BackendChoice:
    requested: str
    used: str
    reason: str
    renderer: str = ""

    @property
    def summary(self):
        """A few words for the Track panel, e.g. 'fast (the GPU is llvmpipe, software)'."""
        name = self.renderer.split(" (")[0]
        if self.requested == self.used and self.requested != "auto":
            why = f"asked for, on {name}" if name else "asked for"
        elif self.used == "gpu":
            why = f"GPU: {name}"
        elif name:
            why = f"the GPU is {name}, software"
        else:
            why = "no usable GPU"
        return f"{self.used} ({why})"

    def to_dict(self):
        return {"requested": self.requested, "used": self.used, "reason": self.reason,
                **({"gpu_renderer": self.renderer} if self.renderer else {})}


def _probe_command():
    import bpy

    binary = getattr(bpy.app, "binary_path", "")  # empty in the bpy module
    if binary:
        return [binary, "--background", "--factory-startup", "--python-expr", _PROBE_SCRIPT]
    return [sys.executable, "-c", _PROBE_SCRIPT]  # bpy as a Python module


_probe_result = None


def probe_gpu(timeout=PROBE_TIMEOUT_S):
    """{'ok': bool, 'renderer': ..., 'error': ...} from a subprocess that draws and reads back a triangle.
    Cached for the process."""
    global _probe_result
    if _probe_result is not None:
        return _probe_result
    try:
        proc = subprocess.run(_probe_command(), capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as exc:
        _probe_result = {"ok": False, "error": f"the probe could not run ({type(exc).__name__}: {exc})"}
        return _probe_result
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("MOCAP_GPU_PROBE ")), None)
    if line is None:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        _probe_result = {"ok": False, "error": f"the probe process ended with code {proc.returncode} ({tail})"}
    else:
        _probe_result = json.loads(line.split(" ", 1)[1])
    return _probe_result


def _cpu_choice(requested, why, renderer=""):
    from ..core import render

    used = render.resolve_backend("auto")
    return BackendChoice(requested, used, why + ("numba CPU path" if used == "fast" else
                                                 "NumPy reference path (numba is not installed)"), renderer)


def choose_backend(requested="auto"):
    """The backend a run uses. Raises BackendUnavailableError (one line naming the fix) when "gpu" or "fast"
    is asked for and cannot run here."""
    from ..core import render

    if requested not in render.BACKENDS:
        raise render.BackendUnavailableError(f"unknown backend {requested!r}; choose one of "
                                             f"{', '.join(render.BACKENDS)}")
    if requested == "numpy":
        return BackendChoice("numpy", "numpy", "asked for: NumPy reference path")
    if requested == "fast":
        try:
            render.resolve_backend("fast")
        except ImportError as exc:
            raise render.BackendUnavailableError(str(exc)) from exc
        return BackendChoice("fast", "fast", "asked for: numba CPU path")
    from ..addon import gpu_likelihood

    probe = probe_gpu()
    renderer = probe.get("renderer", "")
    if requested == "gpu":
        if not probe.get("ok"):
            raise render.BackendUnavailableError(
                f"the GPU likelihood cannot start here ({probe.get('error', 'probe failed')}): {FIX}")
        gpu_likelihood.install()
        return BackendChoice("gpu", "gpu", f"asked for: GLSL path on {renderer}", renderer)
    if not probe.get("ok"):
        return _cpu_choice("auto", f"no usable GPU ({probe.get('error', 'probe failed')}): ")
    if gpu_likelihood.is_software(renderer):
        return _cpu_choice("auto", f"the GPU is a software rasteriser ({renderer}), slower than the CPU path: ",
                           renderer)
    gpu_likelihood.install()
    return BackendChoice("auto", "gpu", f"GPU found: GLSL path on {renderer}", renderer)
