"""Track: solve the subject's pose frame by frame and key it on the armature as each frame is solved.

The engine work (`TrackSession.solve_next`) runs in a worker thread; it never touches bpy. Estimates
come back through a queue that a 0.1 s window-manager timer drains on the main thread, where they are
keyed (`TrackSession.key`) and the panel's progress is updated. Esc / right-click asks the session to
stop after the current frame; the keys already made stay and `finish()` writes what was solved.
Without an event loop (background mode, tests) `execute` runs the same steps synchronously.
"""
import time
import traceback
from pathlib import Path

import bpy

from ..core.errors import InputError
from ..core.results.views_without_landmarks import views_without_landmarks_message
from .failures import USER_ERRORS, user_message
from .modal_run import begin_modal, end_modal, is_cancel_key, show_status
from .worker_job import WorkerJob

# The real class lives in track_session.py, which pulls in the whole engine: it is imported on first
# use so that enabling the add-on stays fast. Tests replace this name with a fake session.
TrackSession = None


def _session_class():
    global TrackSession
    if TrackSession is None:
        from .track_session import TrackSession as session_cls

        TrackSession = session_cls
    return TrackSession


class TrackSetupError(InputError):
    """The Track panel is missing something the run needs."""


def output_folder(context):
    """The scene's output folder, else the preference, else 'mocap_result' next to the saved .blend."""
    from ..addon.preferences import get_preferences

    folder = context.scene.mocap.output_dir
    if not folder:
        prefs = get_preferences(context)
        folder = prefs.default_output_dir if prefs is not None else ""
    if not folder:
        if not bpy.data.filepath:
            raise TrackSetupError("No output folder: set one in Mocap > Track (or save the .blend file, then "
                                  "results go to a 'mocap_result' folder next to it)")
        folder = "//mocap_result"
    return Path(bpy.path.abspath(folder))


def run_settings(context):
    """The Track panel's TrackingSettings with the backend resolved (the preferences' choice, the GPU probed)
    and that choice, shown in the panel; a TrackSetupError naming the fix when it cannot run here."""
    from ..addon.preferences import effective_backend
    from ..core.render import BackendUnavailableError
    from ..core.tracking.options import settings_from_choices
    from .backend_choice import choose_backend

    props = context.scene.mocap
    try:
        choice = choose_backend(effective_backend(context, props.backend))
    except BackendUnavailableError as exc:
        raise TrackSetupError(str(exc)) from exc
    settings = settings_from_choices(props, backend=choice.used)  # as the command line's settings_from_args
    props.backend_used = choice.summary  # the whole reason goes to report.json
    return settings, choice


def build_session(context, log=None, step=None):
    """Read the scene's settings and construct the tracking session (main thread).

    `log(message)` receives the session's messages, `step(text, fraction)` its one-off preparation
    (text None when it is over); both may be called from any thread.
    """
    from .setup_subject import subject_armatures

    props = context.scene.mocap
    if not props.capture_dir:
        raise TrackSetupError("No capture folder: set it in Mocap > Capture and import the capture first")
    armatures = subject_armatures(context)
    settings, choice = run_settings(context)
    capture_dir = Path(bpy.path.abspath(props.capture_dir))
    if len(armatures) > 1:
        return _cast_session(context, armatures, capture_dir, settings, choice, log, step)
    armature = armatures[0]
    extra = {}
    if props.use_actor and props.actor_file:  # the Calibrate step's result (Subject panel)
        from ..core.actor.actor_file import load_actor

        extra["actor"] = load_actor(bpy.path.abspath(props.actor_file))
    session = _session_class()(context.scene, armature, capture_dir, output_folder(context), settings,
                               frames=props.frame_range(), resume=props.resume, log=log, step=step,
                               units=None if props.units == "auto" else props.units, smooth_hz=props.smoothing_hz,
                               foot_lock=props.foot_lock, foot_lock_speed=props.foot_lock_speed, **extra)
    writer = getattr(session, "writer", None)
    if writer is not None:
        writer.info["backend"] = choice.to_dict()  # report.json
    return session


def _cast_session(context, armatures, capture_dir, settings, choice, log, step):
    """Several actors (operators/cast_session.py): every armature solved in one frame loop."""
    from .cast_session import CastSession

    props = context.scene.mocap
    if props.use_actor and props.actor_file:
        raise TrackSetupError("An actor calibration applies to one actor: untick 'Track with Calibration' to track "
                              "every armature, or untick 'Track Every Armature'")
    cast = CastSession(context.scene, armatures, capture_dir, output_folder(context), settings=settings,
                       frames=props.frame_range(), resume=props.resume, log=log, step=step,
                       units=None if props.units == "auto" else props.units, smooth_hz=props.smoothing_hz,
                       foot_lock=props.foot_lock, foot_lock_speed=props.foot_lock_speed,
                       actors=_cast_actors(context, armatures, capture_dir))
    for session in cast.sessions:
        session.writer.info["backend"] = choice.to_dict()  # report.json
    return cast


def _cast_actors(context, armatures, capture_dir):
    """Each actor's build fitted on this capture (Fit the Actor's Build saved it in the actor's result folder), or
    None for an actor without one (tracked with the rig); None when the panel tracks with the rig."""
    from .calibrate import calibration_made_on, cast_actor_file

    if not context.scene.mocap.fit_actor_build:
        return None
    capture = Path(capture_dir).resolve()
    actors = [calibration_made_on(str(cast_actor_file(context, a)), capture) for a in armatures]
    return actors if any(a is not None for a in actors) else None


class TrackJob(WorkerJob):
    """One run of a session: solving in a worker thread (or inline), keying on the caller's thread.

    Thread rule (operators/worker_job.py): the worker calls only `session.solve_next()` and puts plain results
    on the queue; everything else (keys, properties, finish) happens where `drain` / `run_inline` / `finish`
    are called.
    """
    thread_name = "mocap-track"
    doing = "Tracking"

    def __init__(self):
        super().__init__()
        self.session = None
        self.estimates = []
        self.error = None  # text naming what failed, or None
        self.cancelled = False
        self.status = ""  # the session's latest message; shown until the next frame arrives
        self.step = None  # (text, fraction) of the one-off preparation while it runs
        self.out_dir = None
        self.started = time.perf_counter()
        self._done_before = 0
        self._total = 0

    # ---- progress relay: the session may call this from any thread
    def report_progress(self, *args, **_kwargs):
        self.queue.put(("status", " ".join(str(a) for a in args)))

    def report_step(self, text, fraction=0.0):
        self.queue.put(("step", text, float(fraction)))

    def _attach(self, session):
        self.session = session
        self._total = int(getattr(session, "n_total", 0) or len(session.frames))
        self._done_before = max(0, self._total - len(session.frames))
        self.started = time.perf_counter()

    @property
    def fraction(self):
        if self._total <= 0:
            return 1.0 if self.done else 0.0
        return min(1.0, (self._done_before + len(self.estimates)) / self._total)

    @property
    def seconds_per_frame(self):
        return sum(e.seconds for e in self.estimates) / len(self.estimates) if self.estimates else 0.0

    @property
    def recent_seconds_per_frame(self):
        """Mean time of the last five frames; the first frame's whole-body search leaves it once later
        frames are in (it takes several times longer than a tracked frame)."""
        recent = self.estimates[1:][-5:] or self.estimates[-1:]
        return sum(e.seconds for e in recent) / len(recent) if recent else 0.0

    @property
    def seconds_left(self):
        left = max(0, self._total - self._done_before - len(self.estimates))
        return left * self.recent_seconds_per_frame

    # ---- threaded run
    def start(self, session):
        self._attach(session)
        self.start_worker()

    def work(self):
        while not self.cancelled:
            estimate = self.session.solve_next()
            if estimate is None:
                break
            self.queue.put(("frame", estimate))

    # ---- messages, on the main thread: drain() returns the estimates keyed
    def on_frame(self, estimate):
        return estimate if self._key(estimate) else None

    def on_status(self, text):
        self.status = text

    def on_step(self, text, fraction):
        self.step = None if text is None else (text, min(1.0, max(0.0, fraction)))

    def on_error(self, message, details):
        self._fail(message, details)

    def _key(self, estimate):
        if self.error is not None:
            return False
        try:
            self.session.key(estimate)
        except Exception as exc:  # e.g. the armature was deleted while tracking
            self._fail(f"keying frame {estimate.frame} failed: {type(exc).__name__}: {exc}", traceback.format_exc())
            self.request_cancel()
            return False
        self.estimates.append(estimate)
        self.status, self.step = "", None  # a message belongs to the moment it was sent, not to every later frame
        return True

    def _fail(self, message, details):
        if details:
            print(details)
        if self.error is None:
            self.error = message

    def request_cancel(self):
        if not self.cancelled:
            self.cancelled = True
            self.session.cancel()

    # ---- synchronous run (no event loop)
    def run_inline(self, session, on_frame=None):
        self._attach(session)
        try:
            while not self.cancelled:
                estimate = session.solve_next()
                if estimate is None:
                    break
                if self._key(estimate) and on_frame is not None:
                    on_frame(estimate)
        except Exception as exc:  # noqa: BLE001  (reported; the frames solved before it stay keyed)
            self._fail(*self.describe_failure(exc))
        self.drain()  # status messages
        self.done = True

    def finish(self, export=True):
        """Wait for the worker, key what is left, write the results. Returns the session's summary."""
        self.join()
        self.done = True
        return self.session.finish(export=export)


def _duration(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def _status_line(job):
    """One line for the current moment: the preparation step while it runs, else the frame count."""
    done = job._done_before + len(job.estimates)
    if job.step is not None and not job.estimates:
        text, fraction = job.step
        return f"Preparing (once per rig): {text}, {100 * fraction:.0f} %"
    if not job.estimates:
        line = f"Frame {done + 1} of {job._total}: solving"
        if done == job._done_before:
            line += " (the first frame searches the whole body)"
    elif len(job.estimates) == 1 and job._done_before == 0 and done < job._total:
        # the first frame's whole-body search says nothing about the tracked frames' pace
        line = (f"Frame 1 of {job._total}, {job.estimates[0].seconds:.1f} s (the first frame's whole-body "
                f"search); time left after frame 2")
    else:
        line = (f"Frame {done} of {job._total}, {job.recent_seconds_per_frame:.1f} s/frame, "
                f"about {_duration(job.seconds_left)} left")
    return f"{line} - {job.status}" if job.status else line


class MOCAP_OT_track(bpy.types.Operator):
    """Track the subject through the capture, keying each frame as it is solved (Esc to cancel)"""

    bl_idname = "mocap.track"
    bl_label = "Track"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        props = context.scene.mocap if context.scene is not None else None
        return props is not None and not props.is_tracking and not props.is_calibrating  # one engine run at a time

    # ---- shared
    def _begin(self, context):
        job = TrackJob()
        props = context.scene.mocap
        props.last_error = ""
        try:
            session = build_session(context, log=job.report_progress, step=job.report_step)
            if props.resume and hasattr(session, "key_all"):
                session.key_all()  # frames solved by the earlier run get their keys back
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            props.last_error = user_message(exc, "Starting the tracking")
            self.report({"ERROR"}, props.last_error)
            return None, None
        job.out_dir = output_folder(context)
        props.is_tracking = True
        props.progress = 0.0
        props.frames_solved = 0
        props.frames_total = int(getattr(session, "n_total", 0) or len(session.frames))
        props.seconds_per_frame = 0.0
        props.status = "Starting"
        return job, session

    def _show(self, context, job):
        props = context.scene.mocap
        props.preparing = job.step is not None and not job.estimates and not job.done
        props.progress = job.step[1] if props.preparing else job.fraction
        props.frames_solved = job._done_before + len(job.estimates)  # a resumed run counts the earlier frames
        props.frames_total = job._total
        props.seconds_per_frame = job.seconds_per_frame
        props.status = "Cancelling after the current frame" if job.cancelled and not job.done else _status_line(job)

    def _end(self, context, job):
        props = context.scene.mocap
        props.is_tracking = False  # before finish(): it saves tracked.blend
        props.preparing = False
        summary = None
        try:
            summary = job.finish()
        except USER_ERRORS as exc:  # the keys made stay (a full disk, a folder made read-only meanwhile)
            job._fail(f"writing the results failed: {exc}", "")
        except Exception as exc:  # noqa: BLE001  (a bug: said so, the keys made stay)
            job._fail(user_message(exc, "Writing the results"), "")
        self._show(context, job)
        if summary is not None:
            props.last_output = str(job.out_dir)
        solved = len(job.estimates)
        if job.error:
            props.last_error = job.error
            props.status = f"Stopped after {solved} frames: {job.error}"
            self.report({"ERROR"}, f"Tracking stopped after {solved} frames: {job.error}")
            return {"CANCELLED"}
        if job.cancelled:
            props.status = f"Cancelled after {solved} frames (keys kept)"
            self.report({"WARNING"}, f"Tracking cancelled after {solved} frames; their keys are kept")
            return {"CANCELLED"}
        smoothed = f", smoothed at {props.smoothing_hz:g} Hz" if summary and "joints_raw" in summary else ""
        if solved == 0 and job._done_before:  # a finished take resumed: only the smoothing ran again
            again = (f"smoothed again at {props.smoothing_hz:g} Hz" if smoothed else
                     "rewritten as solved (no smoothing)")
            props.status = f"All {job._done_before} frames were already tracked; the take {again}"
            # the status bar's line: what happened first ("Tracked 0 frames" read as a failure)
            done = (f"Smoothed again at {props.smoothing_hz:g} Hz" if smoothed else "Rewritten as solved, unsmoothed")
            report = f"{done}: all {job._done_before} frames were already tracked; results in {props.last_output}"
        else:
            locked = ", feet locked" if summary and "joints_unpinned" in summary else ""
            props.status = f"Tracked {solved} frames, {job.seconds_per_frame:.1f} s/frame{smoothed}{locked}"
            report = f"Tracked {solved} frames{smoothed}{locked}; results in {props.last_output}"
        writer = getattr(job.session, "writer", None)  # one actor's session (several actors: theirs are expected)
        said = views_without_landmarks_message(writer.info) if writer is not None and summary is not None else None
        self.report({"WARNING"} if said else {"INFO"}, f"{report}. {said}" if said else report)
        return {"FINISHED"}

    # ---- synchronous: background mode, scripts, tests
    def execute(self, context):
        if context.scene.mocap.run_on != "this":  # chunks on local processes or a cluster: track_batch.py
            from .track_batch import start

            return start(self, context)
        if not self._calibrate_first_here(context):
            return {"CANCELLED"}
        job, session = self._begin(context)
        if job is None:
            return {"CANCELLED"}
        return self._run_foreground(context, job, session)

    def _calibrate_first_here(self, context):
        """Fit the Actor's Build, synchronously, when Track should (operators/calibrate.py); False when it failed."""
        from .calibrate import calibrate_here, calibration_first, report_calibration

        if not calibration_first(context):
            return True
        props = context.scene.mocap
        try:
            fits = calibrate_here(context)
        except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
            props.last_error = user_message(exc, "Fitting the actor's build")
            self.report({"ERROR"}, f"{props.last_error} (untick Fit the Actor's Build to track with the rig's)")
            return False
        report_calibration(self, props, fits)
        return True

    def _run_foreground(self, context, job, session):
        interactive = not bpy.app.background

        def on_frame(estimate):
            self._show(context, job)
            print(f"mocap: frame {estimate.frame} solved in {estimate.seconds:.2f} s "
                  f"({len(job.estimates)}/{job._total - job._done_before}), energy {estimate.energy:.4g}")
            if interactive:
                context.window_manager.progress_update(int(100 * job.fraction))

        if interactive:
            context.window_manager.progress_begin(0, 100)
        try:
            job.run_inline(session, on_frame)
        finally:
            if interactive:
                context.window_manager.progress_end()
        return self._end(context, job)

    # ---- modal: the UI stays responsive while the worker solves
    def invoke(self, context, _event):
        if context.window is None or context.scene.mocap.run_on != "this":
            return self.execute(context)
        from .calibrate import calibration_first

        if calibration_first(context):  # the actor's build first (modal, Esc cancels); it starts Track once saved
            try:
                result = bpy.ops.mocap.calibrate_actor("INVOKE_DEFAULT", then_track=True)
            except RuntimeError:  # it could not start: it said why (last_error)
                return {"CANCELLED"}
            return {"FINISHED"} if result & {"RUNNING_MODAL", "FINISHED"} else {"CANCELLED"}
        job, session = self._begin(context)
        if job is None:
            return {"CANCELLED"}
        if getattr(getattr(session, "settings", None), "backend", "") == "gpu":
            # bpy's gpu module works only on the main thread: solve in the foreground (progress bar, no Esc).
            return self._run_foreground(context, job, session)
        self._job = job
        job.start(session)
        return begin_modal(self, context, 0.1)

    def modal(self, context, event):
        job = self._job
        if is_cancel_key(event):
            job.request_cancel()
            self._refresh(context, job)
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        new = job.drain()
        if new:  # show the newest solved pose in the viewport
            to_scene = getattr(job.session, "scene_frame", lambda f: f + context.scene.frame_start)
            context.scene.frame_set(to_scene(new[-1].frame))
        if job.error and not job.cancelled:
            job.request_cancel()
        self._refresh(context, job)
        if job.done:
            self._cleanup(context)
            return self._end(context, job)
        return {"RUNNING_MODAL"}

    def _refresh(self, context, job):
        self._show(context, job)
        show_status(context, context.scene.mocap.status)

    def _cleanup(self, context):
        end_modal(self, context)

    def cancel(self, context):
        """Blender ends the operator (file loaded, window closed): stop the worker, keep the keys and
        write the result files for the solved frames, as Esc does."""
        job = self._job
        job.request_cancel()
        job.join()
        self._cleanup(context)
        try:
            self._end(context, job)
        except Exception:  # Blender is tearing the operator down: report, never block it
            traceback.print_exc()
        context.scene.mocap.is_tracking = False


classes = (MOCAP_OT_track,)
