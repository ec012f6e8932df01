"""A batch take of several actors (`armature = ["Lead", "Partner"]` in TAKES.toml): tracked whole by one `track`
command on a worker, not in chunks.

The actors are solved in one frame loop, each seeing the others' bodies (operators/cast_session.py), so a chunk
of a cast would have to start every actor again together; one worker per cast take is what is built. The command
writes into CHUNKS/<take>/cast-<first>-<last>_<key>/ on the shared storage (the key as a chunk's:
core/batch/chunk_folder.py), with --resume, so a retried or rerun take continues from the frames already solved
there, and `cast.json` marks the folder finished by that command; the batch then copies it to DIR/<take>/. A rerun
with other finishing options (--smooth, --no-foot-lock, ...) runs the command again, which only finishes again
(docs/batch.md, "Several actors in a batch").
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from ..core.atomic_files import write_json
from .failures import EXIT_INPUT

DONE_FILE = "cast.json"  # in a cast take's work folder once its `track` has finished


def cast_work_folder(chunks_root, take, key):
    """CHUNKS/<take>/cast-<first>-<last>_<key>: where the take's `track` writes (shared storage)."""
    from ..core.batch.plan import frame_range_name

    return Path(chunks_root) / take.name / f"cast-{frame_range_name(*take.frames)}_{key}"


class CastRun:
    """A take of several actors in the batch: one `track` task, its state and progress (the fields the batch's
    progress and cancel read from a chunked take's TakeRun)."""

    def __init__(self, take, work, argv):
        self.take, self.work, self.argv = take, Path(work), list(argv)
        self.plan = [None]  # counted as one chunk in the progress
        self.futures = {}  # 0 -> the task's future while it runs
        self.attempts = 0
        self.seed_future = self.stitch = None
        self.state, self.error = "queued", None

    @property
    def finished(self):
        """Tracked and finished by the same command (the same take, settings and finishing options)."""
        try:
            return json.loads((self.work / DONE_FILE).read_text()).get("argv") == self.argv
        except (OSError, ValueError, AttributeError):
            return False

    @property
    def chunks_done(self):
        return int(self.finished)

    @property
    def frames_total(self):
        return self.take.n_frames

    def frames_done(self):
        """The frames every actor has solved (each actor's report.json, written as frames are solved)."""
        from ..core.batch.progress import frames_solved

        if self.finished:
            return self.frames_total
        return min((frames_solved(actor) for actor in (self.work / "actors").glob("*/")), default=0)

    def fail(self, reason):
        self.state, self.error = "failed", f"take {self.take.name!r}: {reason}"
        for future in self.futures.values():
            future.cancel()
        self.futures.clear()


def cast_argv(command, take, work, mapped, args):
    """The worker's `track` command for a cast take: every armature, the take's frames and options, --resume (a
    retry continues), --stop-with-parent (a killed worker's command stops), and the batch's finishing options."""
    from .cmd_batch import option_args
    from .cmd_track import foot_lock_args

    argv = [*command, "track", "--scene", mapped(take.scene), "--capture", mapped(take.capture), "--out",
            mapped(work), "--frames", f"{take.frames[0]}-{take.frames[1]}", "--resume", "--stop-with-parent"]
    for name in take.armatures:
        argv += ["--armature", name]
    if take.calibrate is not None:
        argv.append("--calibrate" if take.calibrate else "--no-calibrate")
    for length in take.measured:  # each names its actor (core/batch/takes.py)
        argv += ["--calibrate-measured", length]
    argv += option_args(take.choices) + ["--smooth", str(args.smooth)] + foot_lock_args(args.foot_lock,
                                                                                       args.foot_lock_speed)
    return argv + (["--no-export"] if args.no_export else []) + (["--no-overlays"] if args.no_overlays else [])


def submit_cast(runner, run):
    run.futures[0] = runner.submit(f"{run.take.name}-cast", run.argv, check=False)
    run.state = "running"


def poll_cast(runner, run, out_dir):
    """Advance a cast take: a finished task's result copied to out_dir/<take>/; a failed one run again (it
    resumes) up to the runner's retries, unless the failure is the user's (the same again would fail)."""
    from ..core.batch.cluster import failure_text

    future = run.futures.get(0)
    if future is None:
        return
    status = future.status
    if status == "pending":
        return
    del run.futures[0]
    if status == "finished":
        ended = future.result(timeout=5)
        code = ended.returncode
        if code == 0:
            write_json(run.work / DONE_FILE, {"take": run.take.name, "armatures": list(run.take.armatures),
                                              "frames": list(run.take.frames), "argv": run.argv})
            finish_cast(run, out_dir)
            return
        if code == EXIT_INPUT:
            run.fail(f"track: {failure_text(ended)}")
            return
        reason = failure_text(ended)
    else:
        try:
            reason = failure_text(future.exception(timeout=5)) if status == "error" else status
        except Exception as exc:  # noqa: BLE001  (the reason is reported, whatever it is)
            reason = f"{type(exc).__name__}: {exc}"
    run.attempts += 1
    if run.attempts > runner.retries:
        run.fail(f"track: {reason} (after {run.attempts} runs)")
        return
    submit_cast(runner, run)


def finish_cast(run, out_dir):
    """out_dir/<take>/: the finished work folder's result, copied over whatever an earlier run left there."""
    target = Path(out_dir) / run.take.name
    target.mkdir(parents=True, exist_ok=True)
    shutil.copytree(run.work, target, dirs_exist_ok=True, ignore=shutil.ignore_patterns(DONE_FILE))
    run.state = "done"
