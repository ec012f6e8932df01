"""FBX / BVH export of the tracked armature with settings that keep every tracked frame.

`export_fbx` / `export_bvh` are plain functions (the CLI and the Track session use them too); the
operators only add a file browser. Settings follow blender-and-calibration.md 4.6: no leaf bones,
no curve simplification, start/end keys forced, Blender's bone axes, FBX unit scaling.
"""
import os
from contextlib import contextmanager
from pathlib import Path

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..addon.anim_compat import keyed_frame_range
from ..core.errors import InputError
from .failures import user_message


class ExportError(InputError):
    """Nothing exportable (no keys, no armature) or a frame range that makes no sense."""


def skinned_meshes(armature_obj, scene):
    return [o for o in scene.objects if o.type == "MESH" and any(
        m.type == "ARMATURE" and m.object == armature_obj for m in o.modifiers)]


def _resolve_range(armature_obj, frame_range):
    if frame_range is None:
        frame_range = keyed_frame_range(armature_obj)
        if frame_range is None:
            raise ExportError(f"armature {armature_obj.name!r} has no keyframes to export: track it first "
                              f"(Mocap > Track), or give a frame range")
    start, end = (int(f) for f in frame_range)
    if end < start:
        raise ExportError(f"export frame range {start}-{end} ends before it starts; swap the two frames")
    return start, end


def _view_layer(context, scene):
    """The view layer to export from: the context's when it belongs to `scene`, else the scene's first.

    In `blender --background FILE --command ...` (and in timers) the context may hold no window, no
    view layer and no active object, so nothing here relies on them being set."""
    view_layer = getattr(context, "view_layer", None)
    if view_layer is None or scene is None or view_layer.name not in scene.view_layers \
            or scene.view_layers[view_layer.name] != view_layer:
        view_layer = scene.view_layers[0]
    return view_layer


@contextmanager
def _export_state(context, objects, active, frame_range, scene=None):
    """Object mode, only `objects` selected, `active` active, scene range = frame_range; restored after.

    Yields a dict of context members for `context.temp_override(**members)`: Blender's exporters read
    `context.object` / `context.selected_objects` in their poll and execute, which are missing in a
    `--command` run, so the exporter call is made under an override naming them explicitly."""
    scene = scene or context.scene
    view_layer = _view_layer(context, scene)
    previous_active = view_layer.objects.active
    previous_mode = None
    if previous_active is not None and previous_active.mode != "OBJECT":
        previous_mode = previous_active.mode
        with context.temp_override(scene=scene, view_layer=view_layer, active_object=previous_active,
                                   object=previous_active):
            bpy.ops.object.mode_set(mode="OBJECT")
    selected = [o for o in view_layer.objects if o.select_get(view_layer=view_layer)]
    previous_range = (scene.frame_start, scene.frame_end, scene.frame_current)
    try:
        for o in selected:
            o.select_set(False, view_layer=view_layer)
        for o in objects:
            if o.name not in view_layer.objects:
                raise ExportError(f"{o.name!r} is not in the view layer {view_layer.name!r}; "
                                  f"include its collection to export it")
            o.select_set(True, view_layer=view_layer)
        view_layer.objects.active = active
        scene.frame_start, scene.frame_end = frame_range
        yield dict(scene=scene, view_layer=view_layer, active_object=active, object=active,
                   selected_objects=list(objects), selected_editable_objects=list(objects))
    finally:
        scene.frame_start, scene.frame_end = previous_range[:2]
        scene.frame_set(previous_range[2])
        for o in view_layer.objects:
            o.select_set(o in selected, view_layer=view_layer)
        view_layer.objects.active = previous_active
        if previous_mode is not None:
            with context.temp_override(scene=scene, view_layer=view_layer, active_object=previous_active,
                                       object=previous_active):
                bpy.ops.object.mode_set(mode=previous_mode)


def _prepare_path(path):
    path = Path(bpy.path.abspath(str(path)))
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def export_fbx(context, armature_obj, path, frame_range=None, include_mesh=True,
               scale_options="FBX_SCALE_UNITS", global_scale=1.0, scene=None):
    """Write the armature (and the meshes skinned to it) with its animation baked on every frame."""
    start, end = _resolve_range(armature_obj, frame_range)
    path = _prepare_path(path)
    scene = scene or context.scene
    objects = [armature_obj] + (skinned_meshes(armature_obj, scene) if include_mesh else [])
    with _export_state(context, objects, armature_obj, (start, end), scene) as members, \
            context.temp_override(**members):
        bpy.ops.export_scene.fbx(
            filepath=str(path), use_selection=True, object_types={"ARMATURE", "MESH"},
            global_scale=global_scale, apply_unit_scale=True, apply_scale_options=scale_options,
            axis_forward="-Z", axis_up="Y", primary_bone_axis="Y", secondary_bone_axis="X",
            armature_nodetype="NULL", add_leaf_bones=False, use_armature_deform_only=False,
            bake_anim=True, bake_anim_use_all_bones=True, bake_anim_use_nla_strips=False,
            bake_anim_use_all_actions=False, bake_anim_force_startend_keying=True,
            bake_anim_step=1.0, bake_anim_simplify_factor=0.0)
    return path


def bvh_transform_warning(armature_obj):
    """A message when the armature object is moved/rotated/scaled: BVH files hold armature space only."""
    import numpy as np

    if np.allclose(np.array(armature_obj.matrix_world), np.eye(4), atol=1e-6):
        return ""
    return (f"armature {armature_obj.name!r} has an object transform that is not part of the BVH (Blender's BVH "
            f"exporter writes armature space); apply it (Ctrl+A > All Transforms) before tracking if the BVH must "
            f"match the world")


def export_bvh(context, armature_obj, path, frame_range=None, global_scale=1.0, scene=None):
    """Write the armature's animation as BVH (Blender axes: Z up; BVH has no axis option)."""
    start, end = _resolve_range(armature_obj, frame_range)
    path = _prepare_path(path)
    with _export_state(context, [armature_obj], armature_obj, (start, end), scene) as members, \
            context.temp_override(**members):
        bpy.ops.export_anim.bvh(filepath=str(path), frame_start=start, frame_end=end, global_scale=global_scale,
                                rotate_mode="NATIVE", root_transform_only=False)
    return path


def _default_export_path(context, armature_obj, ext):
    props = context.scene.mocap
    folder = props.last_output or (os.path.dirname(bpy.data.filepath) if bpy.data.filepath else "")
    name = f"{bpy.path.clean_name(armature_obj.name)}_mocap{ext}"
    return os.path.join(bpy.path.abspath(folder), name) if folder else name


class _ExportOperator(ExportHelper):
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not context.scene.mocap.is_tracking

    def invoke(self, context, event):
        from .setup_subject import subject_armature

        try:
            arm = subject_armature(context)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            self.report({"ERROR"}, user_message(exc, "Finding the armature to export"))
            return {"CANCELLED"}
        if not self.filepath:
            self.filepath = _default_export_path(context, arm, self.filename_ext)
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from .setup_subject import subject_armature

        try:
            arm = subject_armature(context)
            path = self._export(context, arm)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            self.report({"ERROR"}, user_message(exc, "The export"))
            return {"CANCELLED"}
        warning = self._warning(arm)
        self.report({"WARNING"} if warning else {"INFO"}, f"Exported {arm.name} to {path}"
                    + (f"; {warning}" if warning else ""))
        return {"FINISHED"}

    def _warning(self, _arm):
        return ""


class MOCAP_OT_export_fbx(bpy.types.Operator, _ExportOperator):
    """Export the tracked armature and its mesh as FBX, every frame keyed, no leaf bones"""

    bl_idname = "mocap.export_fbx"
    bl_label = "Export FBX"
    filename_ext = ".fbx"
    filter_glob: StringProperty(default="*.fbx", options={"HIDDEN"})
    include_mesh: BoolProperty(name="Include Mesh", default=True, description="Export the skinned mesh too")
    scale_options: EnumProperty(
        name="Apply Scalings", default="FBX_SCALE_UNITS",
        items=(("FBX_SCALE_NONE", "All Local", "Keep Blender's scale on the objects (1 unit = 1 cm in FBX apps)"),
               ("FBX_SCALE_UNITS", "FBX Units Scale", "Scale to FBX centimetres (Unreal, Unity import at the "
                                                      "right size)"),
               ("FBX_SCALE_CUSTOM", "FBX Custom Scale", "Apply the custom scale to the FBX unit scale"),
               ("FBX_SCALE_ALL", "FBX All", "Apply both unit and custom scale to the FBX unit scale")))

    def _export(self, context, arm):
        return export_fbx(context, arm, self.filepath, include_mesh=self.include_mesh,
                          scale_options=self.scale_options)


class MOCAP_OT_export_bvh(bpy.types.Operator, _ExportOperator):
    """Export the tracked armature's animation as BVH (the keyed frame range)"""

    bl_idname = "mocap.export_bvh"
    bl_label = "Export BVH"
    filename_ext = ".bvh"
    filter_glob: StringProperty(default="*.bvh", options={"HIDDEN"})
    global_scale: FloatProperty(name="Scale", default=1.0, min=0.0001, max=1e6,
                                description="Scale applied to positions (e.g. 100 for centimetres)")

    def _warning(self, arm):
        return bvh_transform_warning(arm)

    def _export(self, context, arm):
        return export_bvh(context, arm, self.filepath, global_scale=self.global_scale)


classes = (MOCAP_OT_export_fbx, MOCAP_OT_export_bvh)
