"""`track-chunk`: track one chunk of a take into its chunk folder (core/batch/chunk_folder.py).

The unit of work of `batch` (and of the Flamenco job type): a worker runs it as a command of its own, with the
take's subject, capture and settings and the chunk's frames (a chunk plan's `track` range, core/batch/plan.py). It
tracks as `track` does, from the first-frame search at the chunk's first frame, and writes no keys, exports or
overlays: `stitch` makes the take's result folder. With several --armature it tracks those actors together, as
`track` does, each into CHUNK/actors/<armature>/. A finished chunk is never tracked again (exit 0 at once).
"""
import sys
from dataclasses import dataclass
from pathlib import Path

from .cmd_track import (StepPrinter, add_tracking_options, open_subject, parent_watch, parse_frames,
                        settings_from_args)
from .failures import EXIT_PARENT_GONE


def add_take_arguments(p, frames_help):
    """The arguments that name a take and how it is tracked: the chunk's, the seeds', the stitch's."""
    p.add_argument("--scene", type=Path, required=True, help="SUBJECT.blend holding the armature and its skinned mesh")
    p.add_argument("--capture", type=Path, required=True, help="capture folder (calibration + videos/)")
    p.add_argument("--take", required=True, help="the take's name (names its folders)")
    p.add_argument("--frames", required=True, help=frames_help)
    p.add_argument("--chunks", type=Path, required=True, help="the folder of the chunk folders (shared storage)")
    p.add_argument("--armature", action="append",
                   help="armature to track if the scene has several; repeat it for a take of several actors")
    p.add_argument("--actor", action="append", metavar="[ARMATURE=]FILE",
                   help="an actor calibration (actor.json) to track with; with several armatures say whose, as in "
                        "--actor Partner=FILE")
    add_tracking_options(p)


def add_arguments(p):
    add_take_arguments(p, "the chunk's frames A-B, inclusive (a chunk plan's `track` range)")
    p.add_argument("--stop-with-parent", action="store_true",
                   help=f"stop (exit {EXIT_PARENT_GONE}) when the process that started this one ends (a batch "
                        "worker killed mid-chunk: its chunk is run again elsewhere)")


@dataclass
class TakeActors:
    """Who a take tracks: per actor its armature's name (None: the scene's one), its actor calibration (dict or
    None) and, in a take of several, its result folder's name under actors/ (None for one actor)."""
    names: list
    calibrations: list
    folders: list

    @property
    def several(self):
        return len(self.names) > 1


def take_inputs(args, backend=None):
    """(settings, TakeActors, chunk key) of a take's arguments; `backend`: the one resolved."""
    from ..core.actor.actor_file import load_actor
    from ..core.actor.per_actor import options_of
    from ..core.batch.chunk_folder import check_take_name, chunk_key
    from .cast_session import cast_folders

    check_take_name(args.take)
    if not args.scene.is_file():
        from ..core.errors import InputError

        raise InputError(f"--scene {args.scene}: no such file")
    settings = settings_from_args(args, backend)
    names = list(args.armature or [None])
    saved = [options_of(args, name)[0] for name in names]
    calibrations = [None if path is None else load_actor(path) for path in saved]
    if len(names) == 1:  # one actor's key as it always was, so its finished chunks stay valid
        actors = TakeActors(names, calibrations, [None])
        return settings, actors, chunk_key(settings.to_dict(), args.scene, names[0], calibrations[0], args.capture)
    actors = TakeActors(names, calibrations, cast_folders(names))
    return settings, actors, chunk_key(settings.to_dict(), args.scene, names, calibrations, args.capture)


def take_session(scene, actors, capture, out, settings, frames, **options):
    """The take's TrackSession (one actor) or CastSession (several, each into out/actors/<armature>/)."""
    from ..addon.scene_bridge import find_armature
    from .cast_session import CastSession
    from .track_session import TrackSession

    armatures = [find_armature(scene, name) for name in actors.names]
    common = {"settings": settings, "frames": frames, "log": lambda m: print(m, file=sys.stderr),
              "step": StepPrinter(), **options}
    if not actors.several:
        return TrackSession(scene, armatures[0], capture, out, actor=actors.calibrations[0], **common)
    return CastSession(scene, armatures, capture, out, actors=actors.calibrations, **common)


def sessions_of(session):
    """Each actor's TrackSession of a take's session (one, or a CastSession's)."""
    return list(getattr(session, "sessions", [session]))


def run(args):
    from ..core.batch.chunk_folder import ChunkFolder
    from ..core.batch.seed import find_seed
    from ..core.render import BackendUnavailableError
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure

    parent_gone = parent_watch()
    frames = parse_frames(args.frames)
    try:
        settings, actors, key = take_inputs(args)
        folder = ChunkFolder(args.chunks, args.take, (frames[0], frames[-1]), key)
    except USER_ERRORS as exc:
        return cli_failure("track-chunk", exc)
    if folder.done:
        print(f"chunk already tracked: {folder.path}", file=sys.stderr)
        print(folder.path)
        return 0
    scene = open_subject(args.scene)
    try:
        choice = choose_backend(args.backend)
    except BackendUnavailableError as exc:
        print(f"markerless_mocap track-chunk: {exc}", file=sys.stderr)
        return 2
    partial = None
    try:
        partial = folder.new_partial()
        session = take_session(scene, actors, args.capture, partial, settings_from_args(args, choice.used), frames,
                               smooth_hz=0)
        seeded = []
        for each, part in zip(sessions_of(session), actors.folders):
            seed = find_seed(args.chunks, args.take, key, frames[0], actor=part)
            if seed is not None:  # the person where the take's seed pass found them, not the subject's placement
                each.rough_pose = seed
            seeded.append(seed is not None)
            each.writer.info["backend"] = choice.to_dict()
            each.writer.info["chunk"] = {"take": args.take, "track": [frames[0], frames[-1]], "key": key}
        while True:
            if args.stop_with_parent and parent_gone():
                print("markerless_mocap track-chunk: the process that started this chunk has ended; stopping "
                      "(the chunk is run again elsewhere)", file=sys.stderr)
                return EXIT_PARENT_GONE
            est = session.solve_next()
            if est is None:
                break
            print(f"chunk {folder.path.name}: frame {est.frame} ({session.n_done} of {session.n_total}), "
                  f"{est.seconds:.2f} s", file=sys.stderr, flush=True)
        for each in sessions_of(session):
            each.tracker.finish_prefetch()
        names = [each.armature.name for each in sessions_of(session)]
        path = folder.publish(partial, {"backend": choice.used, "frames": session.n_done,
                                        "start": "seeds" if all(seeded) else "placement",
                                        "capture": str(Path(args.capture).resolve()),
                                        "scene": str(args.scene.resolve()),
                                        "armature": names if actors.several else names[0]})
        partial = None
    except USER_ERRORS as exc:
        return cli_failure("track-chunk", exc)
    finally:
        if partial is not None:
            import shutil

            shutil.rmtree(partial, ignore_errors=True)
    print(path)
    return 0
