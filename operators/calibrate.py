"""The Calibrate step of the Subject panel: fit the actor's proportions on the first frames, show them,
apply them to a copy of the rig for inspection. Tracking then uses the calibration (Track with Calibration)."""
from pathlib import Path

import bpy

from .failures import user_message
from .modal_run import begin_modal, end_modal, is_cancel_key, show_status


def _calibration_frames(props):
    """The first `calibrate_frames` frames of the range the Track panel tracks."""
    start = props.frame_start if props.use_frame_range else 0
    end = start + props.calibrate_frames - 1
    if props.use_frame_range:
        end = min(end, props.frame_end)
    return range(start, end + 1)


def _measured(props, whose=""):
    """The lengths measured on the actor that `props` holds (the panel's settings, or an armature's
    mocap_measured): {"height" or segment: metres}, those set (> 0); a MeasuredLengthError naming the field (after
    `whose`) of one that is no length of a person."""
    from ..addon.properties import MEASURED_SEGMENTS
    from ..core.actor.measured_lengths import MeasuredLengthError, checked_length

    fields = [("height", "actor_height")] + [(key, f"actor_{key}") for key, _label, _where in MEASURED_SEGMENTS]
    measured = {}
    for name, field in fields:
        metres = getattr(props, field)
        if metres <= 0:
            continue
        try:
            measured[name] = checked_length(name, metres)
        except MeasuredLengthError as exc:
            label = props.bl_rna.properties[field].name
            raise MeasuredLengthError(f"{whose}{label}: {exc}") from None
    return measured


def calibration_first(context):
    """Whether Track fits the actors' builds before tracking (Fit the Actor's Build): tracking on this Blender, not
    resuming, no calibration of this capture loaded (one actor) or saved in every actor's folder (several,
    cast_actor_file), and a take at least Calibration Frames long."""
    from ..core.errors import InputError
    from .setup_subject import subject_armatures

    props = context.scene.mocap
    if not props.fit_actor_build or props.resume or props.run_on != "this" or not props.capture_dir:
        return False  # (no capture: Track itself names the fix)
    capture = Path(bpy.path.abspath(props.capture_dir)).resolve()
    try:
        armatures = subject_armatures(context)
        if len(armatures) == 1:
            fitted = calibration_made_on(props.actor_file, capture) is not None
        else:
            fitted = all(calibration_made_on(str(cast_actor_file(context, a)), capture) is not None for a in armatures)
        if fitted:
            return False
        from .cmd_track import take_frames

        return len(take_frames(capture, props.frame_range())) >= props.calibrate_frames
    except InputError:  # no armature to track, a bad capture or range: Track's own start says what and how to fix it
        return False


def calibration_made_on(actor_file, capture):
    """The calibration in `actor_file` (the Subject panel's, or one of several actors' saved by Track) if it was made
    on this capture, else None: Track then uses it and fits none."""
    if not actor_file:
        return None
    from ..core.actor.actor_file import load_actor
    from ..core.errors import InputError

    try:
        data = load_actor(bpy.path.abspath(actor_file))
    except (InputError, OSError):
        return None
    made_on = data.get("capture")
    return data if made_on and Path(made_on).resolve() == capture else None


def cast_actor_file(context, armature):
    """Where the build of one of several actors is saved: its result folder's actor.json (OUT/actors/<armature>/), as
    `track --armature A --armature B` saves it."""
    from ..core.results.result_folder import ACTORS_FOLDER, actor_folder_name
    from .track import output_folder

    return Path(output_folder(context)) / ACTORS_FOLDER / actor_folder_name(armature.name) / "actor.json"


def _inputs(context):
    """What to fit: [(armature, its output folder)] (one actor: the output folder; several: each one's folder of
    cast_actor_file), the capture folder and the panels' tracking settings."""
    from .setup_subject import subject_armature, subject_armatures
    from .track import TrackSetupError, output_folder, run_settings

    props = context.scene.mocap
    if not props.capture_dir:
        raise TrackSetupError("No capture folder: set it in Mocap > Capture and import the capture first")
    actors = subject_armatures(context)
    if len(actors) > 1:
        targets = [(a, cast_actor_file(context, a).parent) for a in actors]
    else:
        targets = [(actors[0] if len(actors) == 1 else subject_armature(context), output_folder(context))]
    settings, _ = run_settings(context)
    return targets, Path(bpy.path.abspath(props.capture_dir)), settings


def measured_lengths_for(props, armatures):
    """Per armature the lengths measured on its actor: the Subject panel's for one actor, each armature's own
    (Object.mocap_measured) for several."""
    if len(armatures) == 1:
        return [_measured(props)]
    return [_measured(armature.mocap_measured, f"{armature.name}: ") for armature in armatures]


def calibrate_here(context):
    """Fit each actor on the panels' calibration frames on this thread and save it: [(ProportionsFit, actor.json)]
    in the order of _inputs."""
    from .actor_calibration import calibrate_actor

    targets, capture_dir, settings = _inputs(context)
    props = context.scene.mocap
    measured = measured_lengths_for(props, [armature for armature, _folder in targets])
    return [calibrate_actor(context.scene, armature, capture_dir, out_dir, settings, frames=_calibration_frames(props),
                            measured=lengths)
            for (armature, out_dir), lengths in zip(targets, measured)]


def show_calibration(props, actor_path, lines):
    props.actor_file = str(actor_path)
    props.actor_summary = "\n".join(lines)
    props.use_actor = True


def report_calibration(operator, props, fits):
    """Saved fits [(fit, actor.json)] into the Subject panel and the status bar: one actor's summary (Track with
    Calibration on); several actors' each in its own folder, where Track finds them (cast_actor_file)."""
    from .actor_calibration import describe

    if len(fits) == 1:
        fit, path = fits[0]
        lines = describe(fit)
        show_calibration(props, path, lines)
        operator.report({"INFO"}, f"Actor calibrated: {lines[0]}; saved {path}")
        return
    said = "; ".join(f"{path.parent.name}: {describe(fit)[0]}" for fit, path in fits)
    operator.report({"INFO"}, f"{len(fits)} actors calibrated ({said}); saved in their result folders")


class MOCAP_OT_calibrate_actor(bpy.types.Operator):
    """Fit the actor's height and segment lengths to the first frames of the capture (tracks them with the rig,
    fits the proportions to the learned landmarks, then the forearm and hip width to the person masks); saved as
    actor.json in the output folder (Esc to cancel)"""

    bl_idname = "mocap.calibrate_actor"
    bl_label = "Calibrate Actor"
    bl_options = {"REGISTER"}

    # set by Track (Fit the Actor's Build): once the fit is saved, Track starts with it
    then_track: bpy.props.BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        props = context.scene.mocap if context.scene is not None else None
        return props is not None and not props.is_tracking and not props.is_calibrating

    def _fail(self, context, message):
        context.scene.mocap.last_error = message
        self.report({"ERROR"}, message)
        return {"CANCELLED"}

    def _show_result(self, context, fits):
        report_calibration(self, context.scene.mocap, fits)
        if self.then_track:
            try:
                bpy.ops.mocap.track("INVOKE_DEFAULT")
            except RuntimeError:
                pass  # Track could not start: it said why in the panel (last_error) and the status bar
        return {"FINISHED"}

    # ---- synchronous: background mode, scripts, tests, the GPU backend (bpy's gpu works on the main thread only)
    def execute(self, context):
        try:
            fits = calibrate_here(context)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            return self._fail(context, user_message(exc, "The calibration"))
        return self._show_result(context, fits)

    # ---- modal: the UI stays responsive while the worker tracks the calibration frames and fits
    def invoke(self, context, _event):
        if context.window is None:
            return self.execute(context)
        props = context.scene.mocap
        try:
            targets, capture_dir, settings = _inputs(context)
            if settings.backend == "gpu":
                return self.execute(context)
            # checked before anything is tracked
            measured = measured_lengths_for(props, [armature for armature, _folder in targets])
            self._queue = [(armature, out_dir, lengths) for (armature, out_dir), lengths in zip(targets, measured)]
            self._capture, self._settings, self._fits = capture_dir, settings, []
            self._start_next(context)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            return self._fail(context, user_message(exc, "Starting the calibration"))
        props.last_error = ""
        props.is_calibrating = True
        props.calibration_status = "Calibrating: starting"
        return begin_modal(self, context, 0.2)

    def _start_next(self, context):
        """Open the next actor's calibration (main thread: it reads the rig) and start its worker."""
        from .actor_calibration import CalibrationJob, open_calibration

        armature, out_dir, self._measured = self._queue.pop(0)
        session = open_calibration(context.scene, armature, self._capture, out_dir, self._settings,
                                   frames=_calibration_frames(context.scene.mocap))
        self._job = CalibrationJob(session, len(session.frames))
        self._save_args = (out_dir, armature.name, self._capture)
        self._job.start()

    def modal(self, context, event):
        job = self._job
        if is_cancel_key(event):
            job.request_cancel()
        elif event.type != "TIMER":
            return {"PASS_THROUGH"}
        job.drain()
        props = context.scene.mocap
        props.calibration_progress = job.fraction
        props.calibration_status = ("Calibrating: cancelling after the current frame" if job.cancelled
                                    else f"Calibrating: {job.status}")
        show_status(context, props.calibration_status)
        return self._end(context) if job.done else {"RUNNING_MODAL"}

    def _end(self, context):
        from .actor_calibration import save_calibration

        job = self._job
        finished = job.error is None and job.fit is not None
        if finished:
            from ..core.actor.measured_lengths import with_measured

            fit = with_measured(job.fit, job.session.character, self._measured)
            try:
                self._fits.append((fit, save_calibration(fit, *self._save_args)))
            except Exception as exc:  # noqa: BLE001
                job.error = (f"could not save the calibration: {user_message(exc, 'Saving it')}", None)
                finished = False
        if finished and self._queue:  # the next of several actors
            try:
                self._start_next(context)
                return {"RUNNING_MODAL"}
            except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
                job.error, finished = (user_message(exc, "Starting the calibration"), None), False
        end_modal(self, context)
        props = context.scene.mocap
        props.is_calibrating = False
        props.calibration_status = ""
        if job.error is not None:
            if job.error[1]:
                print(job.error[1])
            return self._fail(context, job.error[0])
        if not finished:  # cancelled before the fit
            saved = ", ".join(path.parent.name for _fit, path in self._fits)  # of several actors, those done
            self.report({"WARNING"}, f"Calibration cancelled after {job.solved} frames; "
                                     + (f"saved for {saved} only" if saved else "nothing saved"))
            return {"CANCELLED"}
        return self._show_result(context, self._fits)

    def cancel(self, context):
        """Blender ends the operator (file loaded, window closed): stop the worker, save nothing."""
        self._job.request_cancel()
        self._job.join()
        end_modal(self, context)
        context.scene.mocap.is_calibrating = False


class MOCAP_OT_apply_actor_copy(bpy.types.Operator):
    """Make a copy of the rig and its mesh with the calibrated proportions, to compare with the footage
    (the rig itself is not changed)"""

    bl_idname = "mocap.apply_actor_copy"
    bl_label = "Apply to a Copy"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..addon.actor_bridge import apply_proportions_to_copy
        from ..core.actor.actor_file import load_actor, proportions_for_body
        from ..addon.scene_bridge import body_from_blender
        from .setup_subject import subject_armature

        from ..core.errors import InputError

        props = context.scene.mocap
        try:
            if not props.actor_file:
                raise InputError("no actor calibration yet: press Calibrate Actor first (or load an actor.json)")
            data = load_actor(bpy.path.abspath(props.actor_file))
            armature = subject_armature(context)
            proportions = proportions_for_body(data, body_from_blender(armature, None, context.scene))
            arm_copy, _ = apply_proportions_to_copy(context.scene, armature, proportions)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            self.report({"ERROR"}, user_message(exc, "Applying the calibration to a copy"))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{arm_copy.name}: the rig with the actor's proportions "
                              f"(height {data['height_m']:.3f} m)")
        return {"FINISHED"}


classes = (MOCAP_OT_calibrate_actor, MOCAP_OT_apply_actor_copy)
