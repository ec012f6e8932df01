"""`track-chunk`: track one chunk of a take into its chunk folder (core/batch/chunk_folder.py).

The unit of work of `batch` (and of the Flamenco job type): a worker runs it as a command of its own, with the
take's subject, capture and settings and the chunk's frames (a chunk plan's `track` range, core/batch/plan.py). It
tracks as `track` does, from the first-frame search at the chunk's first frame, and writes no keys, exports or
overlays: `stitch` makes the take's result folder. A finished chunk is never tracked again (exit 0 at once).
"""
import sys
from pathlib import Path

from .cmd_track import (StepPrinter, add_tracking_options, open_subject, parent_watch, parse_frames,
                        settings_from_args)
from .failures import EXIT_PARENT_GONE



def add_take_arguments(p, frames_help):
    """The arguments that name a take and how it is tracked: the chunk's, the stitch's."""
    p.add_argument("--scene", type=Path, required=True, help="SUBJECT.blend holding the armature and its skinned mesh")
    p.add_argument("--capture", type=Path, required=True, help="capture folder (calibration + videos/)")
    p.add_argument("--take", required=True, help="the take's name (names its folders)")
    p.add_argument("--frames", required=True, help=frames_help)
    p.add_argument("--chunks", type=Path, required=True, help="the folder of the chunk folders (shared storage)")
    p.add_argument("--armature", help="armature to track if the scene has several")
    p.add_argument("--actor", type=Path, help="an actor calibration (actor.json) to track with")
    add_tracking_options(p)


def add_arguments(p):
    add_take_arguments(p, "the chunk's frames A-B, inclusive (a chunk plan's `track` range)")
    p.add_argument("--stop-with-parent", action="store_true",
                   help=f"stop (exit {EXIT_PARENT_GONE}) when the process that started this one ends (a batch "
                        "worker killed mid-chunk: its chunk is run again elsewhere)")


def take_inputs(args, backend=None):
    """(settings, actor dict or None, chunk key) of a take's arguments; `backend`: the one resolved."""
    from ..core.actor.actor_file import load_actor
    from ..core.batch.chunk_folder import check_take_name, chunk_key

    check_take_name(args.take)
    if not args.scene.is_file():
        from ..core.errors import InputError

        raise InputError(f"--scene {args.scene}: no such file")
    settings = settings_from_args(args, backend)
    actor = load_actor(args.actor) if args.actor is not None else None
    return settings, actor, chunk_key(settings.to_dict(), args.scene, args.armature, actor, args.capture)


def run(args):
    from ..addon.scene_bridge import find_armature
    from ..core.batch.chunk_folder import ChunkFolder
    from ..core.batch.seed import find_seed
    from ..core.render import BackendUnavailableError
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure
    from .track_session import TrackSession

    parent_gone = parent_watch()
    frames = parse_frames(args.frames)
    try:
        settings, actor, key = take_inputs(args)
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
        armature = find_armature(scene, args.armature)
        settings = settings_from_args(args, choice.used)
        partial = folder.new_partial()
        session = TrackSession(scene, armature, args.capture, partial, settings, frames=frames,
                               log=lambda m: print(m, file=sys.stderr), step=StepPrinter(), actor=actor, smooth_hz=0)
        seed = find_seed(args.chunks, args.take, key, frames[0])
        if seed is not None:  # the person where the take's seed pass found them, not the subject's placement
            session.rough_pose = seed
        session.writer.info["backend"] = choice.to_dict()
        session.writer.info["chunk"] = {"take": args.take, "track": [frames[0], frames[-1]], "key": key}
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
        session.tracker.finish_prefetch()
        path = folder.publish(partial, {"backend": choice.used, "frames": session.n_done,
                                        "start": "placement" if seed is None else "seeds",
                                        "capture": str(Path(args.capture).resolve()),
                                        "scene": str(args.scene.resolve()), "armature": armature.name})
        partial = None
    except USER_ERRORS as exc:
        return cli_failure("track-chunk", exc)
    finally:
        if partial is not None:
            import shutil

            shutil.rmtree(partial, ignore_errors=True)
    print(path)
    return 0
