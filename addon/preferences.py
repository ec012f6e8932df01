"""Add-on preferences: defaults that hold across scenes (tracker backend, where results go)."""
import bpy
from bpy.props import EnumProperty, StringProperty

from .properties import BACKENDS

# This file sits in addon/, so the add-on's own package is the parent (e.g. "bl_ext.user_default.markerless_mocap").
ADDON_PACKAGE = __package__.rpartition(".")[0]


class MocapPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_PACKAGE

    default_backend: EnumProperty(
        name="Default Backend", items=BACKENDS, default="auto",
        description="Backend used when a scene's tracker backend is left at Auto")
    default_output_dir: StringProperty(
        name="Default Output Folder", subtype="DIR_PATH",
        description="Result folder used when a scene sets none (blank: a 'mocap_result' folder next to the .blend)")

    def draw(self, _context):
        layout = self.layout
        layout.prop(self, "default_backend")
        layout.prop(self, "default_output_dir")


def get_preferences(context=None):
    """The add-on's preferences, or None when the add-on is not enabled (e.g. modules used directly)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_PACKAGE)
    return addon.preferences if addon else None


def effective_backend(context, scene_backend):
    """A scene's backend, with Auto replaced by the preference when that names one."""
    prefs = get_preferences(context)
    if scene_backend == "auto" and prefs is not None:
        return prefs.default_backend
    return scene_backend


classes = (MocapPreferences,)


register, unregister = bpy.utils.register_classes_factory(classes)
