"""`stitch`: a take's finished chunks (core/batch/) into the take's result folder, as `track` writes it.

The chunks are found again from the take's plan and settings (the chunk folders' names); their kept frames are
cross-faded over each overlap (core/batch/stitch.py), then the take is smoothed, keyed and exported by the same
TrackSession `track` uses. report.json gains a "batch" section: the plan, each chunk's folder and time, and per
overlap how far the two chunks disagreed. A take of several actors is stitched actor by actor and finished as
`track` finishes several (OUT/actors/<armature>/, one tracked.blend, overlays of all).
"""
import sys
from pathlib import Path

from .cmd_plan_chunks import add_chunk_arguments
from .cmd_track import add_foot_lock_options, add_smooth_option, finish_and_list, open_subject, parse_frames
from .cmd_track_chunk import add_take_arguments, sessions_of, take_inputs, take_session


def add_arguments(p):
    add_take_arguments(p, "the take's frames F0-F1, inclusive (as planned)")
    add_chunk_arguments(p)
    p.add_argument("--out", type=Path, required=True, help="the take's result folder")
    add_smooth_option(p, "the stitched take")
    p.add_argument("--no-export", action="store_true", help="skip animation.bvh/.fbx and tracked.blend")
    p.add_argument("--no-overlays", action="store_true", help="skip the overlay videos")
    add_foot_lock_options(p)


def missing_chunks(folders):
    """The chunk folders not finished yet, as text naming their frames ('' when none)."""
    return ", ".join(f"{f.track[0]}-{f.track[1]}" for f in folders if not f.done)


def run(args):
    from ..core.actor.actor_file import write_actor
    from ..core.batch.chunk_folder import ChunkError, ChunkFolder
    from ..core.batch.plan import plan_chunks, plan_to_json
    from ..core.batch.stitch import stitch
    from ..core.batch.stitch_report import per_frame_facts
    from ..core.results.views_without_landmarks import views_without_landmarks_message
    from .failures import USER_ERRORS, cli_failure

    frames = parse_frames(args.frames)
    try:
        settings, actors, key = take_inputs(args)
        plan = plan_chunks(frames[0], frames[-1], args.chunk_frames, args.warmup, args.overlap)
        folders = [ChunkFolder(args.chunks, args.take, c.track, key) for c in plan]
        missing = missing_chunks(folders)
        if missing:
            raise ChunkError(f"take {args.take!r}: chunks {missing} are not tracked yet in {args.chunks} (with "
                             "these settings); run their track-chunk commands or the batch first")
        infos = [f.info() for f in folders]
        unseeded = [f"{f.track[0]}-{f.track[1]}" for f, i in zip(folders, infos)
                    if f.track[0] > frames[0] and i.get("start") != "seeds"]
        if unseeded:
            raise ChunkError(f"take {args.take!r}: chunks {', '.join(unseeded)} started from the subject's placement, "
                             "not from the take's seeds (core/batch/seed.py): delete their folders, run seed-chunks, "
                             "then track them again")
        estimates = [[f.estimates(part) for f in folders] for part in actors.folders]
        facts = [per_frame_facts(plan, [f.report(part) for f in folders]) for part in actors.folders]
        scene = open_subject(args.scene)
        session = take_session(scene, actors, args.capture, args.out, settings, frames, smooth_hz=args.smooth,
                               foot_lock=args.foot_lock, foot_lock_speed=args.foot_lock_speed)
        stitched = [stitch(each.body, plan, mine) for each, mine in zip(sessions_of(session), estimates)]
    except USER_ERRORS as exc:
        return cli_failure("stitch", exc)
    for each, (poses, overlaps), mine, fit in zip(sessions_of(session), stitched, facts, actors.calibrations):
        writer = each.writer
        if fit is not None:  # beside the take, where Blender's Track reads the build to key it with
            write_actor(writer.out / "actor.json", fit)
        writer.estimates = poses
        writer.info["backend"] = sorted({i.get("backend") for i in infos if i.get("backend")})
        writer.info["batch"] = {
            **plan_to_json(frames[0], frames[-1], args.chunk_frames, args.warmup, args.overlap),
            "chunk_folders": [str(f.path) for f in folders],
            "chunk_hosts": [i.get("host") for i in infos],
            "overlaps": overlaps,
            "overlap_mean_joint_mm": _mean([o["mean_joint_mm"] for o in overlaps]),
            "note": "per frame, 'seconds' is the time of the chunk the frame was kept from; the overlaps' "
                    "mean_joint_mm: the 15 joints' mean distance between the two chunks' solved poses there"}
        writer.info.update(mine)
        writer.write()
    session.key_all()
    actors_said = f" of {len(actors.names)} actors" if actors.several else ""
    finish_and_list(session, args, f"stitched {len(plan)} chunks, {len(stitched[0][0])} frames{actors_said}")
    for each in sessions_of(session):
        said = views_without_landmarks_message(each.writer.info, actors=len(actors.names))
        if said:
            print(f"{each.armature.name}: {said}" if actors.several else said, file=sys.stderr)
    return 0


def _mean(values):
    values = [v for v in values if v is not None]
    return round(sum(values) / len(values), 2) if values else None
