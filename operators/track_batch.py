"""Track on local processes or a Dask cluster (the Track panel's Run On): the take, or every capture of a folder, goes
to the batch runner (`batch`, operators/cmd_batch.py) in a process of its own, cut into chunks.

Blender's part is small and all on the main thread: write the subject .blend and start the process (it never
blocks), read the progress file the batch replaces every few seconds from a `bpy.app.timers` callback (no thread
here, so bpy is never touched off the main thread), and when the batch has ended key the stitched take onto the
armature from its poses.npz, as a finished `track` keys its take.
"""
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np

from ..core.errors import InputError

POLL_SECONDS = 1.0  # the batch replaces its progress file at least every 2 s
_RUNS = {}  # scene name -> BatchRun: the process of each scene's batch (a Popen cannot live in a property)


class BatchSetupError(InputError):
    """The Track panel lacks something a batch needs."""


class ResultMismatchError(InputError):
    """The stitched result does not fit the armature it should be keyed on."""


@dataclass
class BatchRun:
    scene_name: str
    armature_name: str
    out_dir: Path
    process: object  # subprocess.Popen of `batch`
    takes: list  # the take names sent, in order
    frame_offset: int  # scene frame of capture frame 0 (as TrackSession's)
    actor: dict = None  # the actor calibration tracked with, if any
    started: float = field(default_factory=time.time)
    cast: tuple = ()  # several actors' armature names (Track Every Armature): each keyed from actors/<name>/

    @property
    def keyed_take(self):
        """The take keyed on the armature when the batch is done: the one tracked from this scene's capture, or the
        last of a folder."""
        return self.takes[-1]


def take_name(folder):
    """A take name (core/batch/chunk_folder.py's TAKE_NAME) from a capture folder's name."""
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(folder).name).strip("._-")
    return name or "take"


def tracking_choices(props):
    """The Track panel's tracking options as the batch's [defaults] (names as the command line's)."""
    from ..core.tracking.options import CHOICE_NAMES

    choices = {name: getattr(props, name) for name in CHOICE_NAMES}
    choices["refine"] = "icp" if props.refine else "none"  # the panel's checkbox
    return choices


def captures_in(folder):
    """Sub-folders of `folder` holding a calibration, sorted: each is a take."""
    from ..core.capture.calibration import find_calibration_file

    found = []
    for sub in sorted(p for p in Path(folder).iterdir() if p.is_dir() and not p.name.startswith((".", "_"))):
        try:
            find_calibration_file(sub)
        except InputError:
            continue
        found.append(sub)
    return found


def _subject_file(out_dir):
    """The .blend the workers open: the saved file when it has no unsaved changes, else a copy in the batch folder
    (the same bytes every time for the same scene, so an unchanged take resumes)."""
    if bpy.data.is_saved and not bpy.data.is_dirty:
        return Path(bpy.data.filepath)
    target = out_dir / "subject.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(target), copy=True)
    return target


def worker_command():
    """What runs the add-on's command line for the batch and its chunks: Blender itself in the background (the
    add-on registered its command there), or, where bpy is a Python module (no Blender binary), this Python."""
    from . import CLI_NAME

    binary = bpy.app.binary_path
    if binary:
        return [binary, "--background", "--command", CLI_NAME]
    return [sys.executable, "-m", CLI_NAME]


def _measured_lengths(props, armatures):
    """The lengths measured on the actors (the Subject panel's for one, each armature's for several) as the take
    list's `measured` texts (core/batch/takes.py)."""
    from .calibrate import measured_lengths_for

    several = len(armatures) > 1
    out = []
    for armature, lengths in zip(armatures, measured_lengths_for(props, armatures)):
        out += [f"{armature.name}:{name}={metres:g}" if several else f"{name}={metres:g}"
                for name, metres in lengths.items()]
    return out


def plan_takes(context, out_dir, armatures):
    """The [[take]] tables to send: this scene's capture (its frame range), or every capture of the folder;
    `armatures`: the one tracked, or several actors' (one take of them all)."""
    props = context.scene.mocap
    common = {"armature": armatures[0].name if len(armatures) == 1 else [a.name for a in armatures]}
    if props.use_actor and props.actor_file:
        if len(armatures) > 1:
            raise BatchSetupError("An actor calibration applies to one actor: untick 'Track with Calibration' to "
                                  "track every armature, or untick 'Track Every Armature'")
        common["actor"] = bpy.path.abspath(props.actor_file)
    elif not props.fit_actor_build:
        common["calibrate"] = False  # else the batch fits each take's actor first, as Track does here
    else:
        common["measured"] = _measured_lengths(props, armatures) or None  # for that fit
    if props.batch_scope == "folder":
        if not props.batch_folder:
            raise BatchSetupError("No captures folder: set it under Run On in Mocap > Track (each sub-folder with a "
                                  "calibration is a take)")
        folder = Path(bpy.path.abspath(props.batch_folder))
        if not folder.is_dir():
            raise BatchSetupError(f"captures folder {folder} does not exist")
        captures = captures_in(folder)
        if not captures:
            raise BatchSetupError(f"no capture in {folder}: none of its sub-folders holds a calibration "
                                  "(calibration.toml, intri.yml + extri.yml or a *.qca.txt)")
        takes, names = [], set()
        for capture in captures:
            name = take_name(capture)
            while name in names:
                name += "_"
            names.add(name)
            takes.append({"name": name, "capture": str(capture), **common})
    else:
        if not props.capture_dir:
            raise BatchSetupError("No capture folder: set it in Mocap > Capture and import the capture first")
        capture = Path(bpy.path.abspath(props.capture_dir))
        take = {"name": take_name(capture), "capture": str(capture), **common}
        frames = props.frame_range()
        if frames is not None:
            take["frames"] = f"{frames.start}-{frames.stop - 1}"
        takes = [take]
    scene_file = _subject_file(out_dir)
    for take in takes:
        take["scene"] = str(scene_file)
    return takes


def start(operator, context):
    """Send the take(s) and start polling; the operator's result."""
    from ..core.batch.progress import FILE_NAME
    from .cmd_batch import launch_batch
    from .cmd_track import foot_lock_args
    from .failures import user_message
    from .setup_subject import several_actors, subject_armature
    from .track import output_folder

    scene = context.scene
    props = scene.mocap
    props.last_error = ""
    try:
        if props.run_on == "cluster" and not props.scheduler_address.strip():
            raise BatchSetupError("No scheduler address: set it under Run On in Mocap > Track (e.g. "
                                  "tcp://render01:8786), or run on local processes")
        armatures = several_actors(context) or [subject_armature(context)]
        out_dir = output_folder(context)
        out_dir.mkdir(parents=True, exist_ok=True)
        takes = plan_takes(context, out_dir, armatures)
        actor = None
        if "actor" in takes[0]:
            from ..core.actor.actor_file import load_actor

            actor = load_actor(takes[0]["actor"])
        (out_dir / FILE_NAME).unlink(missing_ok=True)  # an earlier batch's: the panel shows only this one's
        process = launch_batch(
            takes, out_dir,
            workers=(props.local_workers or None) if props.run_on == "local" else None,
            scheduler=props.scheduler_address.strip() if props.run_on == "cluster" else None,
            chunk_frames=props.chunk_frames, command=worker_command(), settings=tracking_choices(props),
            extra_args=["--smooth", f"{props.smoothing_hz:g}", *foot_lock_args(props.foot_lock, props.foot_lock_speed),
                        *_cluster_args(props)])
    except Exception as exc:  # noqa: BLE001  (the user's set-up names its fix; anything else is a bug)
        props.last_error = user_message(exc, "Sending the take")
        operator.report({"ERROR"}, props.last_error)
        return {"CANCELLED"}
    cast = tuple(a.name for a in armatures) if len(armatures) > 1 else ()
    run = BatchRun(scene.name, armatures[0].name, out_dir, process, [t["name"] for t in takes], scene.frame_start,
                   actor, cast=cast)
    _RUNS[scene.name] = run
    props.is_tracking = True
    props.batch_dir = str(out_dir)
    props.progress, props.chunks_done, props.chunks_total = 0.0, 0, 0
    props.frames_solved = props.frames_total = 0
    where = "a cluster" if props.run_on == "cluster" else "local processes"
    props.status = f"Sent {len(takes)} take(s) to {where}: planning the chunks"
    scene_name = scene.name
    bpy.app.timers.register(lambda: poll(scene_name), first_interval=0.2)
    operator.report({"INFO"}, f"Tracking {len(takes)} take(s) on {where}; results in {out_dir}")
    return {"FINISHED"}


def _cluster_args(props):
    """The workers' own command, when it is not this Blender's path on every worker."""
    command = props.worker_command.strip() if props.run_on == "cluster" else ""
    return ["--worker-command", command] if command else []


def cancel(scene):
    """Ask the running batch of `scene` to stop (it ends its chunks' processes; finished chunks are kept)."""
    from .cmd_batch import request_cancel

    run = _RUNS.get(scene.name)
    if run is None:
        return False
    request_cancel(run.out_dir)
    scene.mocap.status = "Cancelling: the chunks finished so far are kept (Track again resumes)"
    return True


def _duration(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def show_progress(props, progress):
    """The batch's progress file (operators/cmd_batch.py) in the panel's properties."""
    total = progress.get("total") or {}
    props.chunks_done = int(total.get("chunks_done") or 0)
    props.chunks_total = int(total.get("chunks_total") or 0)
    props.frames_solved = int(total.get("frames_done") or 0)
    props.frames_total = int(total.get("frames_total") or 0)
    props.progress = min(1.0, props.chunks_done / props.chunks_total) if props.chunks_total else 0.0
    state = progress.get("state", "")
    takes = progress.get("takes") or []
    line = f"{state.capitalize()}: chunk {props.chunks_done} of {props.chunks_total}"
    if len(takes) > 1:
        line += f", take {sum(t.get('state') == 'done' for t in takes)} of {len(takes)} done"
    left = total.get("seconds_left")
    if left is not None and state == "running":
        line += f", about {_duration(left)} left"
    props.status = line


def poll(scene_name):
    """The timer: show the progress; once the batch has ended, key the result. Returns the next interval, or None
    to stop (the scene is gone, or the batch ended)."""
    from .cmd_batch import read_progress

    run = _RUNS.get(scene_name)
    scene = bpy.data.scenes.get(scene_name)
    props = getattr(scene, "mocap", None) if scene is not None else None
    if run is None or props is None or props.batch_dir != str(run.out_dir):  # another file loaded: stop watching
        _RUNS.pop(scene_name, None)
        return None
    progress = read_progress(run.out_dir)
    if progress is not None:
        show_progress(props, progress)
    ended = run.process.poll() is not None
    if ended:
        _RUNS.pop(scene_name, None)
        finish(scene, run, read_progress(run.out_dir))
    _redraw()
    return None if ended else POLL_SECONDS


def _log_tail(out_dir, lines=6):
    try:
        text = (Path(out_dir) / "batch.log").read_text(errors="replace")
    except OSError:
        return ""
    return " ".join(line.strip() for line in text.strip().splitlines()[-lines:])


def finish(scene, run, progress):
    """The batch has ended: key its result on the armature and say what happened (main thread)."""
    props = scene.mocap
    props.is_tracking = False
    props.batch_dir = ""
    code = run.process.returncode
    takes = {t.get("name"): t for t in (progress or {}).get("takes") or []}
    # each take's error names the take (operators/cmd_batch.py)
    failed = [t.get("error") or f"take {name!r} failed" for name, t in takes.items() if t.get("state") == "failed"]
    if progress is None or (progress.get("state") == "failed" and not takes):
        reason = (progress or {}).get("error") or _log_tail(run.out_dir) or f"the batch ended with exit code {code}"
        props.last_error = f"The batch did not run: {reason}"
        props.status = "Stopped"
        return False
    if progress.get("state") == "cancelled":
        props.status = f"Cancelled: {props.chunks_done} of {props.chunks_total} chunks done are kept (Track again " \
                       "resumes)"
        return False
    keyed = takes.get(run.keyed_take, {})
    if keyed.get("state") != "done":
        props.last_error = "; ".join(failed) or f"take {run.keyed_take} was not tracked (exit code {code})"
        props.status = f"{len(takes) - len(failed)} of {len(takes)} take(s) tracked; none keyed here"
        return False
    result = Path(keyed.get("result") or run.out_dir / run.keyed_take)
    try:
        frames = _key_each(scene, run, result)
    except Exception as exc:  # noqa: BLE001  (said in the panel; the result folder stays)
        from .failures import user_message

        props.last_error = user_message(exc, "Keying the stitched take")
        props.status = f"Tracked in chunks, not keyed; results in {result}"
        return False
    props.last_output = str(result)
    props.frames_solved = props.frames_total = len(frames)
    props.seconds_per_frame = 0.0
    props.progress = 1.0
    took = _duration(time.time() - run.started)
    chunks = f"{props.chunks_total} chunk{'s' if props.chunks_total != 1 else ''}"
    props.status = f"Tracked {len(frames)} frames in {chunks} in {took}, keyed; results in {result}"
    from ..core.results.views_without_landmarks import views_without_landmarks_in_result

    said = views_without_landmarks_in_result(result)
    if said:  # as Track on this Blender says it (operators/track.py)
        props.status += f". {said}"
    if failed:
        props.last_error = "; ".join(failed)
    return True


def _key_each(scene, run, result):
    """Key the result on the armature, or each actor's (result/actors/<name>/) on its own; the frames keyed."""
    from ..core.results.result_folder import actor_folder_name, actor_result_folder

    targets = [(name, actor_result_folder(result, actor_folder_name(name))) for name in run.cast] or \
        [(run.armature_name, result)]
    for name, folder in targets:
        armature = bpy.data.objects.get(name)
        if armature is None or armature.name not in scene.objects:
            raise ResultMismatchError(f"armature {name!r} is no longer in scene {scene.name!r}: the result is in "
                                      f"{result}")
        frames = key_result(scene, armature, folder, run.frame_offset, run.actor or _fitted_actor(folder))
    return frames


def _fitted_actor(result):
    """The actor calibration the batch fitted for the take (its result folder's actor.json), or None."""
    from ..core.actor.actor_file import load_actor

    return load_actor(result) if (result / "actor.json").is_file() else None


def key_result(scene, armature, result_dir, frame_offset, actor=None):
    """Key the take of a result folder (poses.npz: dof_names, frames, poses) on `armature` at capture frame +
    `frame_offset`, as TrackSession keys a finished take (with an actor calibration, the actor's poses become the
    character's). Returns the capture frames keyed."""
    from ..addon.scene_bridge import body_from_blender, key_pose

    path = Path(result_dir) / "poses.npz"
    try:
        with np.load(path) as data:
            names, frames, poses = [str(n) for n in data["dof_names"]], data["frames"].astype(int), data["poses"]
    except (OSError, KeyError, ValueError) as exc:
        raise ResultMismatchError(f"{path} is not the poses.npz of a result folder ({exc})") from exc
    character = body_from_blender(armature, None, scene)
    body = character
    if actor is not None:
        from ..core.actor.actor_file import actor_body

        body = actor_body(actor, character)
    if names != list(body.dof_names):
        raise ResultMismatchError(f"{path} was tracked with another rig ({len(names)} DOF) than {armature.name!r} "
                                  f"({len(body.dof_names)} DOF): open it on the armature it was tracked with")
    if actor is not None:
        from ..core.actor.proportions import character_poses

        poses = character_poses(body, character, poses, anchor_xy=poses[0][body.translation_dofs[:2]])
    for frame, pose in zip(frames, poses):
        key_pose(armature, character, pose, int(frame) + frame_offset)
    if len(frames):
        scene.frame_start, scene.frame_end = int(frames[0]) + frame_offset, int(frames[-1]) + frame_offset
    return frames


def _redraw():
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type in {"VIEW_3D", "PROPERTIES"}:
                area.tag_redraw()


class MOCAP_OT_cancel_batch(bpy.types.Operator):
    """Stop the take being tracked in chunks; the chunks finished so far are kept and Track resumes them"""

    bl_idname = "mocap.cancel_batch"
    bl_label = "Cancel"
    bl_options = {"REGISTER"}

    def execute(self, context):
        if not cancel(context.scene):
            self.report({"WARNING"}, "No take is being tracked in chunks from this scene")
            return {"CANCELLED"}
        return {"FINISHED"}


classes = (MOCAP_OT_cancel_batch,)
