"""`seed-chunks`: follow a take's person from its first frame with the landmarks alone, so that every chunk that
starts later starts around the person, not where the subject was placed (core/batch/seed.py). One per take, before
its chunks after the first; finished once, never again. A take of several actors follows them all together, each
into a seeds file of its own."""
import shutil
import sys

from .cmd_plan_chunks import add_chunk_arguments
from .cmd_track import open_subject, parse_frames, settings_from_args
from .cmd_track_chunk import add_take_arguments, sessions_of, take_inputs, take_session


def add_arguments(p):
    add_take_arguments(p, "the take's frames F0-F1, inclusive (as planned)")
    add_chunk_arguments(p)


def run(args):
    from ..core.batch.plan import plan_chunks
    from ..core.batch.seed import follow_actors, seed_frames, seeds_path, so_far_path, write_seeds
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure

    frames = parse_frames(args.frames)
    work = None
    try:
        _settings, actors, key = take_inputs(args)
        plan = plan_chunks(frames[0], frames[-1], args.chunk_frames, args.warmup, args.overlap)
        paths = [seeds_path(args.chunks, args.take, frames[0], frames[-1], key, part) for part in actors.folders]
        if all(path.is_file() for path in paths):
            print("\n".join(map(str, paths)))
            return 0
        visit = seed_frames(frames[0], [c.track[0] for c in plan])
        scene = open_subject(args.scene)
        backend = choose_backend(args.backend).used
        work = paths[0].with_name(f".{paths[0].stem}.work")  # the sessions' result folder, unused: removed after
        session = take_session(scene, actors, args.capture, work, settings_from_args(args, backend), frames,
                               smooth_hz=0)
        each = sessions_of(session)
        trackers = [s.prepare() for s in each]

        def write(paths_of, followed, poses, fitted):
            for path, p, f in zip(paths_of, poses, fitted):
                write_seeds(path, followed, p, f)

        try:
            followed, poses, fitted = follow_actors(
                trackers, visit, [s.rough_pose for s in each], progress=lambda i, n, f: print(
                    f"seeds of {args.take}: frame {f} ({i} of {n})", file=sys.stderr, flush=True),
                starts=[c.track[0] for c in plan],
                reached=lambda *so_far: write([so_far_path(p) for p in paths], *so_far))
        finally:
            for tracker in trackers:
                tracker.finish_prefetch()
        write(paths, followed, poses, fitted)
        for path in paths:
            so_far_path(path).unlink(missing_ok=True)
    except USER_ERRORS as exc:
        return cli_failure("seed-chunks", exc)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    placed = [int(f.sum()) for f in fitted]
    said = ", ".join(f"{name} {n}" for name, n in zip(actors.names, placed)) if actors.several else str(placed[0])
    print(f"followed {len(visit)} frames, {said} placed by the landmarks", file=sys.stderr)
    print("\n".join(map(str, paths)))
    return 0
