"""Install a built extension zip into a fresh bpy session and report what happened, as JSON.

Run in its own process with BLENDER_USER_RESOURCES pointing at an empty folder, so it is a real
first install that shares nothing with the caller's bpy:

    python -P tools/install_probe.py install ZIP PACKAGE_ID [MOCAP_OT_class ...]
    python -P tools/install_probe.py restart PACKAGE_ID [MOCAP_OT_class ...]

`install` installs and enables the zip and saves the preferences; `restart` is the next Blender
start on the same user folder. Only after a restart does Blender put the extension's
site-packages (where it unpacked the bundled wheels) ahead of the Python's own, so that is where
cv2/scipy/numba must be imported from and exercised.
"""
import json
import sys
import traceback


def probe(mode, package_id, expected_classes, zip_path=None):
    import bpy  # first: addon_utils lives on the path bpy sets up
    import addon_utils

    report = {"mode": mode, "errors": [], "blender": bpy.app.version_string}
    if mode == "install":
        result = bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True)
        report["install_result"] = sorted(result)
        bpy.ops.wm.save_userpref()
    else:
        bpy.ops.wm.read_userpref()  # Blender loads them at start-up; the bpy module does not
    module = f"bl_ext.user_default.{package_id}"
    report["module"] = module
    report["enabled_in_preferences"] = module in bpy.context.preferences.addons
    report["addon_utils_check"] = list(addon_utils.check(module))
    report["registered_classes"] = [c for c in expected_classes if hasattr(bpy.types, c)]
    report["mocap_ops"] = sorted(dir(bpy.ops.mocap))
    report["extensions_dir"] = bpy.utils.user_resource("EXTENSIONS")
    report["modules"] = {}
    if mode == "restart":
        for name, check in (("cv2", _check_cv2), ("scipy", _check_scipy), ("numba", _check_numba)):
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


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode == "install":
        out = probe(mode, sys.argv[3], sys.argv[4:], zip_path=sys.argv[2])
    else:
        out = probe(mode, sys.argv[2], sys.argv[3:])
    print("PROBE-JSON " + json.dumps(out))
