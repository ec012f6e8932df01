"""The sidebar tab "Mocap" of the 3D viewport: Capture, Subject, Track, Results / Export.

Panels only show `scene.mocap` and call operators; every action lives in operators/.
"""
import textwrap

import bpy

from .properties import CAMERA_COLLECTION, MEASURED_SEGMENTS
from .scene_bridge import scene_armatures, ticked_armatures

CATEGORY = "Mocap"


def _wrapped(layout, text, context, icon="NONE", alert=False):
    """Long messages (errors naming bones or files) as several labels: a sidebar label does not wrap."""
    region = getattr(context, "region", None)
    width = max(20, int((region.width if region else 300) / 7))
    col = layout.column(align=True)
    col.alert = alert
    for i, line in enumerate(textwrap.wrap(text, width) or [""]):
        col.label(text=line, icon=icon if i == 0 else "BLANK1")


class _MocapPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY


class MOCAP_PT_capture(_MocapPanel, bpy.types.Panel):
    bl_idname = "MOCAP_PT_capture"
    bl_label = "Capture"

    def draw(self, context):
        props = context.scene.mocap
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.prop(props, "capture_dir", text="Folder")
        layout.prop(props, "units")
        layout.operator("mocap.import_capture", icon="IMPORT")
        coll = bpy.data.collections.get(CAMERA_COLLECTION)
        cameras = [o for o in coll.objects if o.type == "CAMERA"] if coll else []
        if not cameras:
            layout.label(text="No capture imported", icon="INFO")
            return
        render = context.scene.render
        fps = render.fps / render.fps_base
        box = layout.box()
        box.label(text=f"{len(cameras)} cameras, {props.capture_frames} frames at {fps:g} fps", icon="CAMERA_DATA")
        col = box.column(align=True)
        for obj in cameras:
            size = obj.get("mocap_resolution")
            size_text = f"{int(size[0])}x{int(size[1])}" if size is not None else ""
            active = context.scene.camera == obj
            col.label(text=f"{obj.name}  {size_text}", icon="VIEW_CAMERA" if active else "OUTLINER_OB_CAMERA")


class MOCAP_PT_subject(_MocapPanel, bpy.types.Panel):
    bl_idname = "MOCAP_PT_subject"
    bl_label = "Subject"

    def draw(self, context):
        props = context.scene.mocap
        layout = self.layout
        _draw_armature(layout, props, context)
        layout.operator("mocap.check_subject", icon="ARMATURE_DATA")
        if not props.subject_checked:
            return
        box = layout.box()
        if props.subject_dofs:
            box.label(text=f"{props.subject_dofs} DOF, preset: {props.subject_preset}", icon="CHECKMARK")
        if props.subject_problems:
            _wrapped(box, props.subject_problems, context, icon="ERROR", alert=not props.subject_dofs)
        _draw_calibration(layout.box(), props, context)


def _draw_armature(layout, props, context):
    """The Armature field, and while it is empty the armature tracking will use: the scene's only one, or a
    request to pick one when there are several (tracking would stop there), or all of them as several actors."""
    objects = scene_armatures(context.scene)
    armatures = [o.name for o in objects]
    if len(armatures) > 1:
        layout.prop(props, "every_armature")
        if props.every_armature:
            column = layout.column(align=True)
            for ob in objects:   # which armatures are actors: a character only receiving motion is unticked
                column.prop(ob, "mocap_actor", text=ob.name)
            actors = [o.name for o in ticked_armatures(context.scene)]
            if len(actors) > 1:
                _wrapped(layout, f"Tracks {len(actors)} actors at once: {', '.join(actors)}", context,
                         icon="COMMUNITY")
            elif actors:
                layout.label(text=f"Tracks {actors[0]} alone", icon="ARMATURE_DATA")
            else:
                _wrapped(layout, "No armature ticked: tick the actors to track", context, icon="ERROR", alert=True)
            return
    if props.armature is not None:
        layout.prop(props, "armature")
        return
    row = layout.row()
    row.alert = len(armatures) > 1
    row.prop(props, "armature")
    if len(armatures) == 1:
        layout.label(text=f"Tracks {armatures[0]}, the scene's only armature", icon="ARMATURE_DATA")
    elif armatures:
        _wrapped(layout, f"{len(armatures)} armatures in the scene ({', '.join(armatures)}): pick the one to "
                         "track", context, icon="ERROR", alert=True)
    else:
        layout.label(text="No armature in the scene: add your rigged character", icon="INFO")


def _draw_calibration(box, props, context):
    """Calibrate step: frames to use, the fitted proportions, a copy of the rig with them."""
    box.label(text="Actor Calibration", icon="CON_SIZELIKE")
    box.prop(props, "calibrate_frames")
    actors = ticked_armatures(context.scene) if props.every_armature else []
    if len(actors) > 1:  # each actor's tape measure on its own armature
        for ob in actors:
            _draw_measured_segments(box, ob.mocap_measured, f"MOCAP_measured_{ob.name}", f"{ob.name}: ", height=True)
    else:
        box.prop(props, "actor_height")
        _draw_measured_segments(box, props, "MOCAP_measured_lengths")
    box.operator("mocap.calibrate_actor", icon="MOD_ARMATURE")
    if props.is_calibrating:
        box.progress(factor=props.calibration_progress, type="BAR", text=props.calibration_status)
        box.label(text="Esc to cancel", icon="CANCEL")
    box.prop(props, "actor_file")
    _draw_actor_summary(box, props, context)
    if props.actor_file:
        box.prop(props, "use_actor")
        box.operator("mocap.apply_actor_copy", icon="DUPLICATE")


def actor_summary_header(first_line):
    """The folded summary's one line, short enough for the sidebar: 'height 1.550 m (rig 1.666 m), measured
    1.550 m' -> 'Actor 1.550 m (rig 1.666 m)'; the whole line is the first one inside."""
    return "Actor " + first_line.split(", ")[0].removeprefix("height ")


def _draw_actor_summary(layout, props, context):
    """The fitted proportions, folded under their first line (the height): a dozen lines of lengths would push
    the Track panel out of view."""
    lines = props.actor_summary.splitlines()
    if not lines:
        return
    header, body = layout.panel("MOCAP_actor_summary", default_closed=True)
    header.label(text=actor_summary_header(lines[0]), icon="CHECKMARK")
    if body is None:
        return
    for line in lines:  # the body's choice and the masks' searches run long
        _wrapped(body, line, context)


def _draw_measured_segments(layout, holder, idname, whose="", height=False):
    """The segments measured on an actor (`holder`: the panel's settings, or an armature's mocap_measured), folded
    away: most users measure at most the height. `height`: the height inside too (several actors)."""
    keys = [("height", "Height")] * height + [(key, label) for key, label, _where in MEASURED_SEGMENTS]
    header, body = layout.panel(idname, default_closed=True)
    set_count = sum(getattr(holder, f"actor_{key}") > 0 for key, _label in keys)
    header.label(text=f"{whose}Measured Lengths" + (f" ({set_count} set)" if set_count else ""))
    if body is None:
        return
    body.label(text="0: as the footage gives it")
    for key, label in keys:
        body.prop(holder, f"actor_{key}", text=label)


class MOCAP_PT_track(_MocapPanel, bpy.types.Panel):
    bl_idname = "MOCAP_PT_track"
    bl_label = "Track"

    def draw(self, context):
        props = context.scene.mocap
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = layout.column()
        settings.enabled = not props.is_tracking
        settings.prop(props, "algorithm")
        settings.prop(props, "likelihood")
        settings.prop(props, "preset")
        col = settings.column(align=True)
        col.prop(props, "particles")
        col.prop(props, "iterations")
        settings.prop(props, "seed")
        settings.prop(props, "refine")
        settings.prop(props, "smoothing_hz", text="Smoothing (Hz)")
        settings.prop(props, "fit_actor_build")
        settings.prop(props, "foot_lock")
        threshold = settings.row()
        threshold.enabled = props.foot_lock
        threshold.prop(props, "foot_lock_speed")
        settings.prop(props, "backend")
        settings.prop(props, "background")
        settings.prop(props, "landmarks")
        if props.backend_used:  # what the last Track chose (auto probes the GPU), wrapped: a label does not wrap
            _wrapped(settings, f"Using: {props.backend_used}", context, icon="INFO")
        settings.prop(props, "use_frame_range")
        rng = settings.column(align=True)
        rng.enabled = props.use_frame_range
        rng.prop(props, "frame_start")
        rng.prop(props, "frame_end")
        settings.prop(props, "output_dir", text="Output")
        settings.prop(props, "resume")
        settings.prop(props, "run_on")
        if props.run_on != "this":
            _draw_batch_settings(settings, props)
        row = layout.row()
        row.scale_y = 1.5
        row.enabled = not props.is_tracking
        row.operator("mocap.track", icon="PLAY")
        if props.batch_dir:  # a take sent to local processes or a cluster: its chunks
            layout.progress(factor=props.progress, type="BAR",
                            text=f"{props.chunks_done}/{props.chunks_total} chunks")
        elif props.is_calibrating:  # Track fits the actor's build first (Fit the Actor's Build)
            layout.progress(factor=props.calibration_progress, type="BAR", text=props.calibration_status)
        elif props.is_tracking and props.preparing:
            layout.progress(factor=props.progress, type="BAR", text=f"Preparing {100 * props.progress:.0f} %")
        elif props.is_tracking or props.frames_solved:
            layout.progress(factor=props.progress, type="BAR",
                            text=f"{props.frames_solved}/{props.frames_total} frames")
        if props.status:
            _wrapped(layout, props.status, context)
        if props.batch_dir:
            layout.operator("mocap.cancel_batch", icon="CANCEL")
        elif props.is_tracking:
            layout.label(text="Esc to cancel (keys made so far are kept)", icon="CANCEL")
        elif props.is_calibrating:
            layout.label(text="Esc to cancel", icon="CANCEL")
        if props.last_error:
            _wrapped(layout, props.last_error, context, icon="ERROR", alert=True)


def _draw_batch_settings(layout, props):
    """Run On: local processes or a scheduler; what is sent and how it is cut into chunks."""
    col = layout.column()
    col.prop(props, "batch_scope")
    if props.batch_scope == "folder":
        col.prop(props, "batch_folder")
    if props.run_on == "local":
        col.prop(props, "local_workers")
    else:
        row = col.row()
        row.alert = not props.scheduler_address.strip()
        row.prop(props, "scheduler_address")
        col.prop(props, "worker_command")
    col.prop(props, "chunk_frames")


class MOCAP_PT_results(_MocapPanel, bpy.types.Panel):
    bl_idname = "MOCAP_PT_results"
    bl_label = "Results / Export"

    def draw(self, context):
        props = context.scene.mocap
        layout = self.layout
        if props.frames_solved:  # a resumed take that only smoothed again timed no frame
            pace = f", {props.seconds_per_frame:.1f} s/frame" if props.seconds_per_frame else ""
            layout.label(text=f"{props.frames_solved} frames{pace}", icon="TIME")
        if props.last_output:
            layout.prop(props, "last_output", text="Folder")
        row = layout.row(align=True)
        row.enabled = not props.is_tracking
        row.operator("mocap.export_fbx", icon="EXPORT")
        row.operator("mocap.export_bvh", icon="EXPORT")


classes = (MOCAP_PT_capture, MOCAP_PT_subject, MOCAP_PT_track, MOCAP_PT_results)


register, unregister = bpy.utils.register_classes_factory(classes)
