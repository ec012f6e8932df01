"""The Calibrate step of the Subject panel: fit the actor's proportions on the first frames, show them,
apply them to a copy of the rig for inspection. Tracking then uses the calibration (Track with Calibration)."""
import traceback
from pathlib import Path

import bpy


def _calibration_frames(props):
    """The first `calibrate_frames` frames of the range the Track panel tracks."""
    start = props.frame_start if props.use_frame_range else 0
    end = start + props.calibrate_frames - 1
    if props.use_frame_range:
        end = min(end, props.frame_end)
    return range(start, end + 1)


def show_calibration(props, actor_path, lines):
    props.actor_file = str(actor_path)
    props.actor_summary = "\n".join(lines)
    props.use_actor = True


class MOCAP_OT_calibrate_actor(bpy.types.Operator):
    """Fit the actor's height and segment lengths to the first frames of the capture (tracks them with the rig,
    fits the proportions to the learned landmarks, then the forearm and hip width to the person masks); saved as
    actor.json in the output folder"""

    bl_idname = "mocap.calibrate_actor"
    bl_label = "Calibrate Actor"
    bl_options = {"REGISTER"}

    def execute(self, context):
        from ..core.proportions_fit import ProportionsFitError
        from .actor_calibration import calibrate_actor, describe
        from .setup_subject import subject_armature
        from .track import TrackSetupError, output_folder, run_settings

        props = context.scene.mocap
        try:
            if not props.capture_dir:
                raise TrackSetupError("No capture folder: set it in Mocap > Capture and import the capture first")
            armature = subject_armature(context)
            settings, _ = run_settings(context)
            fit, path = calibrate_actor(context.scene, armature, Path(bpy.path.abspath(props.capture_dir)),
                                        output_folder(context), settings, frames=_calibration_frames(props))
        except (ValueError, ProportionsFitError, FileNotFoundError, OSError) as exc:
            props.last_error = str(exc)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:
            traceback.print_exc()
            self.report({"ERROR"}, f"Calibration failed unexpectedly ({type(exc).__name__}: {exc}); "
                                   "see the system console and report it")
            return {"CANCELLED"}
        lines = describe(fit)
        show_calibration(props, path, lines)
        self.report({"INFO"}, f"Actor calibrated: {lines[0]}; saved {path}")
        return {"FINISHED"}


class MOCAP_OT_apply_actor_copy(bpy.types.Operator):
    """Make a copy of the rig and its mesh with the calibrated proportions, to compare with the footage
    (the rig itself is not changed)"""

    bl_idname = "mocap.apply_actor_copy"
    bl_label = "Apply to a Copy"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..addon.actor_bridge import apply_proportions_to_copy
        from ..core.actor_file import load_actor, proportions_for_body
        from ..addon.scene_bridge import body_from_blender
        from .setup_subject import subject_armature

        props = context.scene.mocap
        try:
            if not props.actor_file:
                raise ValueError("no actor calibration yet: press Calibrate Actor first (or load an actor.json)")
            data = load_actor(bpy.path.abspath(props.actor_file))
            armature = subject_armature(context)
            proportions = proportions_for_body(data, body_from_blender(armature, None, context.scene))
            arm_copy, _ = apply_proportions_to_copy(context.scene, armature, proportions)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{arm_copy.name}: the rig with the actor's proportions "
                              f"(height {data['height_m']:.3f} m)")
        return {"FINISHED"}


classes = (MOCAP_OT_calibrate_actor, MOCAP_OT_apply_actor_copy)
