"""Run by the real-Blender stage: `blender -b --python enable_addon.py -- SOURCE_PARENT`.

Registers SOURCE_PARENT (the folder holding the checkout as `markerless_mocap/`) as a local extension
repository, enables the add-on from it and saves the preferences (BLENDER_USER_RESOURCES is set by the
stage), so the next Blender start, with --command or with the UI, has it enabled like a real install.
"""
import sys

import addon_utils
import bpy

parent = sys.argv[sys.argv.index("--") + 1]
repos = bpy.context.preferences.extensions.repos
if not any(r.module == "mocapdev" for r in repos):
    repos.new(name="mocapdev", module="mocapdev", custom_directory=parent, source="USER")
module = "bl_ext.mocapdev.markerless_mocap"
addon_utils.enable(module, default_set=True, handle_error=None)
assert module in bpy.context.preferences.addons, "the add-on did not enable"
assert hasattr(bpy.ops.mocap, "track") and hasattr(bpy.types, "MOCAP_PT_track")
bpy.context.preferences.view.show_splash = False  # the UI run starts straight in the scene
bpy.ops.wm.save_userpref()
print(f"STAGE enabled {module} from {parent} in Blender {bpy.app.version_string}")
