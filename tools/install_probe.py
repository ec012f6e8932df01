"""Install a built extension zip into a fresh bpy session and report what happened, as JSON.

Run in its own process with BLENDER_USER_RESOURCES pointing at an empty folder, so it is a real
first install that shares nothing with the caller's bpy:

    python -P tools/install_probe.py install ZIP PACKAGE_ID [MOCAP_OT_class ...]
    python -P tools/install_probe.py restart PACKAGE_ID [MOCAP_OT_class ...]
    python -P tools/install_probe.py install-as PLATFORM ZIP PACKAGE_ID [MOCAP_OT_class ...]

`install` installs and enables the zip and saves the preferences; `restart` is the next Blender
start on the same user folder. Only after a restart does Blender put the extension's
site-packages (where it unpacked the bundled wheels) ahead of the Python's own, so that is where
cv2/scipy/numba/dask/distributed must be imported from and exercised.

`install-as` installs a zip built for another platform (windows-x64 on this Linux): Blender's
platform check, here and in the blender_ext.py process it runs to install, sees PLATFORM, so the
package is installed and enabled as there. Blender picks the wheels to unpack by this machine's
own tag (sysconfig), so none of the zip's compiled foreign wheels is unpacked or loaded (the pure-Python
ones, dask's, are): the add-on enables on the Python's own cv2/scipy/numba.
"""
import importlib.util
import json
import os
import sys
import traceback


def _pretend_platform(platform):
    """Blender's platform check in this process, and in the blender_ext.py processes it starts, sees `platform`."""
    from bl_pkg import bl_extension_utils

    bl_extension_utils.platform_from_this_system = lambda: platform
    real_cmd = bl_extension_utils.blender_ext_cmd

    def cmd_through_this_file(python_args):
        *python, script = real_cmd(python_args)
        return [*python, os.path.abspath(__file__), "blender-ext-as", platform, script]

    bl_extension_utils.blender_ext_cmd = cmd_through_this_file


def _run_blender_ext_as(platform, script, argv):
    """blender_ext.py's command line, with its platform check answering `platform`."""
    spec = importlib.util.spec_from_file_location("_blender_ext_as", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # defines only; its main() runs under __main__ only
    module.platform_from_this_system = lambda: platform
    sys.argv = [script, *argv]
    return module.main(argv)


def probe(mode, package_id, expected_classes, zip_path=None, as_platform=None):
    import bpy  # first: addon_utils lives on the path bpy sets up
    import addon_utils

    if as_platform:
        _pretend_platform(as_platform)
    report = {"mode": mode, "errors": [], "blender": bpy.app.version_string, "as_platform": as_platform}
    if mode == "install":
        try:
            result = bpy.ops.extensions.package_install_files(
                filepath=zip_path, repo="user_default", enable_on_install=True)
            report["install_result"] = sorted(result)
            bpy.ops.wm.save_userpref()
        except RuntimeError as exc:  # bpy raises the operator's error report (e.g. another platform's zip)
            report["install_result"] = ["ERROR"]
            report["install_error"] = str(exc)
    else:
        bpy.ops.wm.read_userpref()  # Blender loads them at start-up; the bpy module does not
    module = f"bl_ext.user_default.{package_id}"
    report["module"] = module
    report["enabled_in_preferences"] = module in bpy.context.preferences.addons
    report["addon_utils_check"] = list(addon_utils.check(module))
    report["registered_classes"] = [c for c in expected_classes if hasattr(bpy.types, c)]
    report["mocap_ops"] = sorted(dir(bpy.ops.mocap))
    report["extensions_dir"] = bpy.utils.user_resource("EXTENSIONS")
    report["package_dir_exists"] = os.path.isdir(os.path.join(report["extensions_dir"], "user_default", package_id))
    site = os.path.join(report["extensions_dir"], ".local", "lib", "python{}.{}".format(*sys.version_info[:2]),
                        "site-packages")
    # what Blender unpacked from the zip's wheels (the .dist-info folders name each wheel)
    report["unpacked"] = sorted(n for n in os.listdir(site) if n.endswith(".dist-info")) if os.path.isdir(site) else []
    report["modules"] = {}
    if mode == "restart":
        for name, check in (("cv2", _check_cv2), ("scipy", _check_scipy), ("numba", _check_numba),
                            ("dask", _check_dask), ("distributed", _check_distributed)):
            try:
                module_obj = __import__(name)
                report["modules"][name] = {"file": module_obj.__file__, "version": module_obj.__version__,
                                           "works": bool(check())}
            except Exception:
                report["errors"].append(f"{name}: {traceback.format_exc(limit=3)}")
    return report


def _check_cv2():
    import cv2
    import numpy as np
    img = np.full((9, 9), 255, np.uint8)
    img[4, 4] = 0
    return float(cv2.distanceTransform(img, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[4, 8]) == 4.0


def _check_scipy():
    from scipy.optimize import minimize_scalar
    return abs(minimize_scalar(lambda x: (x - 1.5) ** 2).x - 1.5) < 1e-6


def _check_numba():
    from numba import njit

    @njit
    def total(n):
        s = 0
        for i in range(n):
            s += i
        return s

    return total(101) == 5050


def _check_dask():
    import dask
    return dask.delayed(sum)([1, 2, 3]).compute(scheduler="sync") == 6


def _check_distributed():
    """A one-worker cluster in this process runs a task: tornado, msgpack and the scheduler all work, and
    the compiled parts of the per-platform wheels (msgpack, pyyaml, markupsafe) loaded, not a fallback."""
    import markupsafe
    import msgpack
    import yaml
    from distributed import Client, LocalCluster

    compiled = (msgpack.Packer.__module__ == "msgpack._cmsgpack" and yaml.__with_libyaml__
                and markupsafe._escape_inner.__module__ == "markupsafe._speedups")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        ran = client.submit(sum, [1, 2, 3]).result(timeout=60) == 6
    return bool(compiled and ran)


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode == "blender-ext-as":
        sys.exit(_run_blender_ext_as(sys.argv[2], sys.argv[3], sys.argv[4:]))
    if mode == "install":
        out = probe(mode, sys.argv[3], sys.argv[4:], zip_path=sys.argv[2])
    elif mode == "install-as":
        out = probe("install", sys.argv[4], sys.argv[5:], zip_path=sys.argv[3], as_platform=sys.argv[2])
    else:
        out = probe(mode, sys.argv[2], sys.argv[3:])
    print("PROBE-JSON " + json.dumps(out))
