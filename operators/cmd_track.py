"""`track`: track a capture with the rigged subject of a .blend and write the result folder."""
import argparse
import os
import sys
import time
from pathlib import Path

from ..core.actor.frames import DEFAULT_FRAMES
from ..core.results.views_without_landmarks import views_without_landmarks_message
from ..core.tracking.foot_contact import CONTACT_SPEED
from ..core.tracking.options import OPTIONS, settings_from_choices
from ..core.tracking.fast_arms import FAST_ARM_FROM, FAST_ARM_TO
from ..core.tracking.smoothing import DEFAULT_CUTOFF_HZ
from .failures import EXIT_PARENT_GONE

ALGORITHMS = OPTIONS["algorithm"].values
LIKELIHOOD_NAMES = OPTIONS["likelihood"].values


def parse_frames(text):
    """'A-B' (inclusive) or 'A' -> range; capture frames count from 0."""
    if text is None:
        return None
    try:
        a, _, b = text.partition("-")
        start, end = int(a), int(b) if b else int(a)
    except ValueError:
        raise SystemExit(f"--frames must look like 0-59 (inclusive, capture frames from 0), got {text!r}") from None
    if end < start:
        raise SystemExit(f"--frames {text}: the end comes before the start")
    return range(start, end + 1)


def add_tracking_options(p):
    """--algorithm, --likelihood, --preset, ... as core/tracking/options.py has them (the Track panel's too)."""
    for option in OPTIONS.values():
        flag = f"--{option.name}"
        if not option.choices:  # a number; particles and iterations default to the preset's
            from_preset = option.name in ("particles", "iterations")
            default = None if from_preset else option.default
            shown = f"the preset's, {option.default} in {OPTIONS['preset'].default}" if from_preset else option.default
            p.add_argument(flag, type=type(option.default), default=default,
                           help=f"{option.description} (default: {shown})")
            continue
        each = "; ".join(f"{c.value}: {c.description}" for c in option.choices)
        p.add_argument(flag, choices=option.values, default=option.default,
                       help=f"{option.description} (default: {option.default}). {each}".replace("%", "%%"))


def settings_from_args(args, backend=None):
    """TrackingSettings from the command line; `backend`: the resolved backend (else the one asked for)."""
    return settings_from_choices(args, backend=backend)


def add_arguments(p):
    p.add_argument("--scene", type=Path, help="SUBJECT.blend holding the armature and its skinned mesh "
                   "(not needed inside `blender --background SUBJECT.blend --command markerless_mocap track`)")
    p.add_argument("--capture", type=Path, required=True, help="capture folder (calibration + videos/)")
    p.add_argument("--out", type=Path, required=True, help="result folder")
    p.add_argument("--frames", help="capture frames A-B, inclusive, from 0 (default: all)")
    p.add_argument("--armature", action="append",
                   help="armature to track if the scene has several; repeat it to track several actors at once, "
                        "each placed roughly at its person (results in OUT/actors/NAME/)")
    p.add_argument("--resume", action="store_true", help="continue after the last solved frame in --out")
    p.add_argument("--stop-with-parent", action="store_true",
                   help=f"stop (exit {EXIT_PARENT_GONE}, the frames solved kept for --resume) when the process that "
                        "started this one ends (a farm worker killed mid-take: run again, it resumes)")
    p.add_argument("--no-export", action="store_true", help="skip animation.bvh/.fbx and tracked.blend")
    p.add_argument("--no-overlays", action="store_true", help="skip the overlay videos")
    actor = p.add_mutually_exclusive_group()
    actor.add_argument("--calibrate", action="store_true", default=None,
                       help="fit the actor's proportions on the first frames first (saved as OUT/actor.json), then "
                            "track with them and key the character with the actor's rotations (the default for one "
                            f"actor on a take of at least {DEFAULT_FRAMES} frames; given, it fits on a shorter one)")
    actor.add_argument("--no-calibrate", dest="calibrate", action="store_false",
                       help="track with the rig's own proportions (no actor calibration)")
    actor.add_argument("--actor", action="append", metavar="[ARMATURE=]FILE",
                       help="reuse a saved actor calibration (actor.json of an earlier take); with several armatures "
                            "name whose, as in Partner=FILE, and repeat it for each actor")
    p.add_argument("--calibrate-frames", help="frames A-B for --calibrate (default: the first 20 tracked)")
    p.add_argument("--calibrate-landmarks-only", action="store_true",
                   help="--calibrate from the landmarks alone (default: then refined against the person masks)")
    p.add_argument("--calibrate-measured", action="append", metavar="[ARMATURE:]SEGMENT=METRES",
                   help="--calibrate with a length measured on the actor in place of the footage's (height, "
                        "forearm, ...; repeat for several); with several armatures name whose, as in "
                        "Partner:height=1.62")
    add_smooth_option(p, "the finished take")
    add_foot_lock_options(p)
    add_tracking_options(p)


def foot_lock_args(on, speed):
    """The command line's words for foot locking (add_foot_lock_options), for a command started elsewhere."""
    return ["--foot-lock" if on else "--no-foot-lock", "--foot-lock-speed", f"{speed:g}"]


def add_smooth_option(p, what):
    p.add_argument("--smooth", type=float, default=DEFAULT_CUTOFF_HZ, metavar="HZ",
                   help=f"low-pass {what} at HZ (default {DEFAULT_CUTOFF_HZ:g}; 0: keep the poses as solved); an "
                        f"arm whose wrist moves faster than {FAST_ARM_FROM:g} m/s keeps its solved angles, fully from "
                        f"{FAST_ARM_TO:g} m/s, so a flung hand is not cut short; the solved poses stay in "
                        "joints_raw.npz / poses_raw.npz")


def add_foot_lock_options(p):
    p.add_argument("--foot-lock", action=argparse.BooleanOptionalAction, default=True,
                   help="pin the finished take's planted feet to the floor by refitting the legs (default: on); the "
                        "take before that stays in joints_unpinned.npz / poses_unpinned.npz")
    p.add_argument("--foot-lock-speed", type=float, default=CONTACT_SPEED, metavar="M_S",
                   help=f"a foot near the floor and slower than this (m/s) is planted (default {CONTACT_SPEED:g})")


class Progress:
    """`frame k of n, energy, s/frame, time left` on stderr, one line per frame. Time left = frames left x
    the last five frames' mean (the first frame's whole-body search is left out once others are in)."""

    def __init__(self, total, done=0):
        self.total, self.done, self.start = total, done, time.perf_counter()
        self.seconds = []

    def __call__(self, est):
        self.done += 1
        self.seconds.append(est.seconds)
        recent = self.seconds[1:][-5:] or self.seconds[-1:]
        left = sum(recent) / len(recent) * (self.total - self.done)
        print(f"frame {self.done} of {self.total} (capture frame {est.frame}): energy {est.energy:.4f}, "
              f"{est.seconds:.2f} s/frame, about {left / 60:.1f} min left", file=sys.stderr, flush=True)


class StepPrinter:
    """The one-off preparation on stderr: one line per step, and one per 10 % within a step."""

    def __init__(self):
        self.last = None
        self.start = None

    def __call__(self, text, fraction):
        if self.start is None:
            self.start = time.perf_counter()
        if text is None:
            print(f"preparing: done in {time.perf_counter() - self.start:.1f} s", file=sys.stderr, flush=True)
            return
        key = (text, int(10 * fraction))
        if key != self.last:
            self.last = key
            print(f"preparing (once per rig): {text}, {100 * fraction:.0f} %", file=sys.stderr, flush=True)


def open_subject(scene_path):
    import bpy

    if scene_path is not None:
        if not scene_path.exists():
            raise SystemExit(f"--scene {scene_path}: no such file")
        bpy.ops.wm.open_mainfile(filepath=str(scene_path.resolve()))
    return bpy.context.scene


class ParentGone(Exception):
    """The process that started this one has ended (--stop-with-parent)."""


def parent_watch():
    """A predicate, true once this process's parent has ended (the process was re-parented): --stop-with-parent."""
    parent = os.getppid()
    return lambda: os.getppid() != parent


def run_session(session, progress=None, log=print, stop=None):
    """Solve and key every frame left; `stop`: a predicate asked before each frame, ParentGone raised when true."""
    progress = progress or Progress(session.n_total, session.n_done)
    while True:
        if stop is not None and stop():
            raise ParentGone
        est = session.solve_next()
        if est is None:
            break
        session.key(est)
        progress(est)
    return session


def load_actor_option(args, scene, armature, backend=None):
    """The actor calibration for --actor FILE, or the one fitted now (saved in --out): by default on a take of at
    least DEFAULT_FRAMES frames, with --calibrate on any; None with --no-calibrate, on a shorter take, or when
    resuming a take that was tracked with the rig."""
    from ..core.actor.actor_file import load_actor
    from ..core.actor.measured_lengths import parse_measured
    from ..core.errors import InputError
    from ..core.actor.per_actor import options_of

    asked = getattr(args, "calibrate", None)  # True: --calibrate, False: --no-calibrate, None: the default
    saved, measured_items = options_of(args, getattr(armature, "name", None))
    measured = parse_measured(measured_items)
    if measured and (asked is False or saved is not None):
        raise InputError("--calibrate-measured applies to the actor calibration; with --actor the saved calibration's "
                         "lengths are used (calibrate again with --measured to change them), with --no-calibrate "
                         "none is made")
    if saved is not None:
        return load_actor(saved)
    if asked is False:
        return None
    if args.resume:
        if (args.out / "actor.json").is_file():
            return load_actor(args.out / "actor.json")  # the calibration the interrupted run used
        if (args.out / "checkpoint.npz").is_file():
            return None  # that run tracked with the rig: its frames and the rest stay one body
    from .actor_calibration import calibrate_actor, describe

    tracked = parse_frames(args.frames)
    frames = parse_frames(args.calibrate_frames)
    if frames is None and tracked is not None:
        frames = tracked[:DEFAULT_FRAMES]
    if asked is None and not measured:
        length = len(take_frames(args.capture, tracked))  # a bad range is said before fitting
        if length < DEFAULT_FRAMES:
            print(f"actor: the take has {length} frames, fewer than the {DEFAULT_FRAMES} the actor calibration fits "
                  "on by default: tracking with the rig's proportions (--calibrate fits on these anyway)",
                  file=sys.stderr)
            return None
    fit, path = calibrate_actor(scene, armature, args.capture, args.out, settings_from_args(args, backend),
                                frames=frames, silhouettes=not args.calibrate_landmarks_only,
                                log=lambda m: print(m, file=sys.stderr), step=StepPrinter(), measured=measured)
    for line in describe(fit):
        print(f"actor: {line}", file=sys.stderr)
    return load_actor(path)


def take_frames(capture_dir, frames=None):
    """The capture frames a take tracks: `frames` checked against the footage (the error the tracking would give),
    or every frame the footage has."""
    from ..core.capture.capture import load_capture

    capture = load_capture(capture_dir)
    try:
        footage = capture.frames
        return list(range(footage.n_frames)) if frames is None else footage.require_frames(frames)
    finally:
        capture.close()


def run(args):
    from ..addon.scene_bridge import find_armature
    from ..core.render import BackendUnavailableError
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure
    from .track_session import TrackSession

    scene = open_subject(args.scene)
    try:
        choice = choose_backend(args.backend)  # before the session: a resumed run checks its settings
    except BackendUnavailableError as exc:
        print(f"markerless_mocap track: {exc}", file=sys.stderr)
        return 2
    names = args.armature or [None]
    if len(names) > 1:
        return run_cast(args, scene, names, choice)
    try:
        armature = find_armature(scene, names[0])
        actor = load_actor_option(args, scene, armature, choice.used)
        session = TrackSession(scene, armature, args.capture, args.out, settings_from_args(args, choice.used),
                               frames=parse_frames(args.frames), resume=args.resume,
                               log=lambda m: print(m, file=sys.stderr), step=StepPrinter(), actor=actor,
                               smooth_hz=args.smooth, foot_lock=args.foot_lock, foot_lock_speed=args.foot_lock_speed)
    except USER_ERRORS as exc:  # the capture, the rig, the settings, the folders: the message names the fix
        return cli_failure("track", exc)
    # printed once the inputs are checked: a bad input's message stays the only line
    print(f"likelihood backend: {choice.used} ({choice.reason})", file=sys.stderr)
    session.writer.info["backend"] = choice.to_dict()  # report.json: what was asked for, what ran, why
    if args.resume:
        session.key_all()
    code = solve_all(session, args.out, args.stop_with_parent)
    if code is not None:
        return code
    if choice.used == "gpu":  # its private render scene must not be saved in tracked.blend
        from ..addon import gpu_likelihood
        gpu_likelihood.release()
    finish_and_list(session, args, f"tracked {session.n_done} frames")
    said = views_without_landmarks_message(session.writer.info)
    if said:
        print(said, file=sys.stderr)
    return 0


def solve_all(session, out, stop_with_parent=False):
    """run_session with the command line's endings: None once every frame is solved, else the exit code, said
    with where the frames solved so far are kept (a TrackSession or a CastSession)."""
    from ..core.results.result_folder import ResultWriteError
    from .failures import cli_failure

    try:
        run_session(session, stop=parent_watch() if stop_with_parent else None)
    except ParentGone:
        print(f"markerless_mocap track: the process that started this one has ended; stopping with {session.n_done} "
              f"frames solved and saved in {out} (run again with --resume)", file=sys.stderr)
        return EXIT_PARENT_GONE
    except KeyboardInterrupt:
        print(f"interrupted: {session.n_done} frames solved and saved in {out} (use --resume to continue)",
              file=sys.stderr)
        return 130
    except ResultWriteError as exc:
        print(f"markerless_mocap track: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001  (a frame's footage the user must fix, or a bug: said which)
        code = cli_failure("track", exc)
        print(f"{session.n_done} frames solved and saved in {out} (use --resume to continue)", file=sys.stderr)
        return code
    return None


def run_cast(args, scene, names, choice):
    """`track` with several --armature: every actor in one frame loop (operators/cast_session.py)."""
    from ..addon.scene_bridge import find_armature
    from ..core.results.result_folder import actor_result_folder
    from .cast_session import CastSession, cast_folders
    from .failures import USER_ERRORS, cli_failure

    try:
        armatures = [find_armature(scene, name) for name in names]
        folders = cast_folders([a.name for a in armatures])
        # each actor's build fitted as one alone, into its own result folder, by default as for one actor
        # (docs/measurements.md, "Other people in the room": the duet gains with it); --no-calibrate: none
        actors = [load_actor_option(argparse.Namespace(**{**vars(args), "armature": list(names),
                                                          "out": actor_result_folder(args.out, folder)}),
                                    scene, a, choice.used)
                  for a, folder in zip(armatures, folders)]
        cast = CastSession(scene, armatures, args.capture, args.out, settings=settings_from_args(args, choice.used),
                           frames=parse_frames(args.frames), resume=args.resume,
                           log=lambda m: print(m, file=sys.stderr), step=StepPrinter(), smooth_hz=args.smooth,
                           foot_lock=args.foot_lock, foot_lock_speed=args.foot_lock_speed, actors=actors)
    except USER_ERRORS as exc:
        return cli_failure("track", exc)
    print(f"likelihood backend: {choice.used} ({choice.reason}); {len(armatures)} actors: {', '.join(names)}",
          file=sys.stderr)
    for session in cast.sessions:
        session.writer.info["backend"] = choice.to_dict()
    if args.resume:
        cast.key_all()
    code = solve_all(cast, args.out, args.stop_with_parent)
    if code is not None:
        return code
    written = cast.finish(export=not args.no_export, overlays=not args.no_overlays, save_blend=not args.no_export)
    print(f"tracked {cast.n_done} frames of {len(armatures)} actors -> {args.out}", file=sys.stderr)
    for name, files in written.items():
        print(f"  {name}: {files}", file=sys.stderr)
    for armature, session in zip(armatures, cast.sessions):
        said = views_without_landmarks_message(session.writer.info, actors=len(armatures))
        if said:
            print(f"{armature.name}: {said}", file=sys.stderr)
    return 0


def finish_and_list(session, args, done):
    """Write the result folder's Blender-side files as --no-export / --no-overlays say and list them on stderr
    under `done` (what was made); `track` and `stitch` end this way."""
    written = session.finish(export=not args.no_export, overlays=not args.no_overlays,
                             save_blend=not args.no_export)
    print(f"{done} -> {args.out}", file=sys.stderr)
    for k, v in written.items():
        print(f"  {k}: {v}", file=sys.stderr)
    return written
