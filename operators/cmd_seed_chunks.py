"""`seed-chunks`: follow a take's person from its first frame with the landmarks alone, so that every chunk that
starts later starts around the person, not where the subject was placed (core/batch/seed.py). One per take, before
its chunks after the first; finished once, never again."""
import shutil
import sys

from .cmd_plan_chunks import add_chunk_arguments
from .cmd_track import StepPrinter, open_subject, parse_frames
from .cmd_track_chunk import add_take_arguments, take_inputs


def add_arguments(p):
    add_take_arguments(p, "the take's frames F0-F1, inclusive (as planned)")
    add_chunk_arguments(p)


def run(args):
    from ..addon.scene_bridge import find_armature
    from ..core.batch.plan import plan_chunks
    from ..core.batch.seed import follow_landmarks, seed_frames, seeds_path, so_far_path, write_seeds
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure
    from .track_session import TrackSession

    frames = parse_frames(args.frames)
    work = None
    try:
        settings, actor, key = take_inputs(args)
        plan = plan_chunks(frames[0], frames[-1], args.chunk_frames, args.warmup, args.overlap)
        path = seeds_path(args.chunks, args.take, frames[0], frames[-1], key)
        if path.is_file():
            print(path)
            return 0
        visit = seed_frames(frames[0], [c.track[0] for c in plan])
        scene = open_subject(args.scene)
        armature = find_armature(scene, args.armature)
        backend = choose_backend(args.backend).used
        work = path.with_name(f".{path.stem}.work")  # TrackSession's result folder, unused: removed after
        session = TrackSession(scene, armature, args.capture, work, take_inputs(args, backend)[0], frames=frames,
                               log=lambda m: print(m, file=sys.stderr), step=StepPrinter(), actor=actor, smooth_hz=0)
        tracker = session.prepare()
        try:
            followed = follow_landmarks(tracker, visit, session.rough_pose, progress=lambda i, n, f: print(
                f"seeds of {args.take}: frame {f} ({i} of {n})", file=sys.stderr, flush=True),
                starts=[c.track[0] for c in plan], reached=lambda *so_far: write_seeds(so_far_path(path), *so_far))
        finally:
            tracker.finish_prefetch()
        write_seeds(path, *followed)
        so_far_path(path).unlink(missing_ok=True)
    except USER_ERRORS as exc:
        return cli_failure("seed-chunks", exc)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    print(f"followed {len(visit)} frames, {int(followed[2].sum())} placed by the landmarks", file=sys.stderr)
    print(path)
    return 0
