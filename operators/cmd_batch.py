"""`batch`: many takes, each cut into chunks, tracked on local processes or a Dask cluster, then stitched.

    python -m markerless_mocap batch TAKES.toml|FOLDER --out DIR [--workers N | --scheduler ADDRESS]
                                     [--chunk-frames K] [--warmup W] [--overlap O] [tracking options]

The takes (core/batch/takes.py) are checked first, every one (a bad input names its take, exit 2, nothing runs).
Each take is planned into chunks (core/batch/plan.py); every chunk not finished in an earlier run is one task: its
`track-chunk` command line, run as a subprocess by a Dask worker (core/batch/cluster.py). When a take's chunks are
all in, its `stitch` command runs here and writes DIR/<take>/ as `track` would. A take whose chunk or stitch fails
is reported with its reason and the others go on. DIR/batch-progress.json says where it stands
(core/batch/progress.py); the Blender panel starts this command with `launch_batch` and polls `read_progress`.
"""
from __future__ import annotations

import hashlib
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

from ..core.atomic_files import write_json
from ..core.batch.progress import (CANCEL_FILE, cancel_requested, frames_solved, progress_lines, read_progress,
                                   request_cancel, write_progress)
from ..core.results.result_folder import ACTORS_FOLDER, actor_result_folder
from ..core.tracking.options import CHOICE_NAMES
from .cmd_plan_chunks import add_chunk_arguments
from .cmd_track import add_foot_lock_options, add_smooth_option, add_tracking_options, foot_lock_args
from .failures import EXIT_INPUT as EXIT_USER_ERROR

EXIT_SOME_FAILED = 1
EXIT_CANCELLED = 130
POLL_SECONDS = 1.0
PRINT_SECONDS = 10.0  # on a non-terminal, a progress line at least this often while frames advance
STITCHED_FILE = "stitched.json"  # beside a take's result: what it was stitched from (a rerun skips the same)


def add_arguments(p):
    p.add_argument("takes", type=Path, help="TAKES.toml ([[take]] tables: name, scene, capture, optional frames, "
                                            "armature, actor and tracking options), or a folder of capture folders")
    p.add_argument("--out", type=Path, required=True, help="the batch's folder: DIR/<take>/ per take")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="local processes tracking chunks at once (default: one per two "
                                                   "cores)")
    where.add_argument("--scheduler", help="a Dask scheduler's address (tcp://host:8786) or scheduler file; its "
                                           "workers need this package and the shared storage (docs/batch.md)")
    add_chunk_arguments(p)
    p.add_argument("--chunks", type=Path, help="where the chunk folders go (default DIR/_chunks; shared storage)")
    p.add_argument("--scene", type=Path, help="the subject for captures without their own subject.blend")
    p.add_argument("--armature", action="append",
                   help="the armature to track in takes that do not name theirs (a folder of captures); repeat it to "
                        "track several actors in each")
    p.add_argument("--worker-command", help="what runs markerless_mocap on a worker, e.g. \"/opt/blender/blender "
                                            "--background --command markerless_mocap\" (default: as here)")
    p.add_argument("--path-map", action="append", default=[], metavar="HERE=THERE",
                   help="a path prefix as this machine sees it and as the workers do (repeat for several)")
    p.add_argument("--retries", type=int, default=2, help="runs of a failed chunk after the first (default 2)")
    p.add_argument("--threads-per-chunk", type=int,
                   help="thread pools of each local chunk process (default: cores / workers)")
    add_smooth_option(p, "each stitched take")
    p.add_argument("--no-calibrate", action="store_true",
                   help="track the takes that do not say `calibrate = true` with the rig's proportions (by default a "
                        "take of at least 20 frames without an `actor` is tracked with the actor's, fitted first)")
    p.add_argument("--no-export", action="store_true", help="skip animation.bvh/.fbx and tracked.blend")
    p.add_argument("--no-overlays", action="store_true", help="skip the overlay videos")
    add_foot_lock_options(p)
    add_tracking_options(p)
    p.set_defaults(**{name: None for name in CHOICE_NAMES})  # unset: the take list's, else the preset's


# ---------------------------------------------------------------- for the Blender panel (no bpy here)
def default_command():
    """The command that runs this package's command line as a separate process: inside Blender, Blender in the
    background with this extension's command; else (bpy as a Python module too) this interpreter with `-m`."""
    package = __package__.rsplit(".", 1)[0]
    name = package.rsplit(".", 1)[-1]
    if "." in package:  # an installed extension (bl_ext.<repository>.<name>)
        import bpy

        if bpy.app.binary_path:  # empty for the bpy module
            return [bpy.app.binary_path, "--background", "--command", name]
    return [sys.executable, "-m", name]


def command_environment(env=None):
    """An environment in which default_command() imports this package as this process did: the folder it was
    imported from (not resolved: a link named after the package counts) first on PYTHONPATH (Blender itself
    ignores it and finds its extensions)."""
    env = dict(os.environ if env is None else env)
    parent = str(Path(__file__).absolute().parents[2])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (parent, env.get("PYTHONPATH")) if p)
    return env


def launch_batch(takes, out_dir, workers=None, scheduler=None, chunk_frames=None, command=None, settings=None,
                 extra_args=()):
    """Start `batch` in a background process; returns the subprocess.Popen (output in out_dir/batch.log). `takes`:
    a TAKES.toml, a folder of captures, or a list of [[take]] dicts (written to out_dir/takes.toml); `settings`:
    tracking options for every take; `command`: what runs markerless_mocap (default_command())."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / CANCEL_FILE).unlink(missing_ok=True)
    if isinstance(takes, (list, tuple)):
        path = out_dir / "takes.toml"
        path.write_text(takes_toml(takes))
        takes = path
    argv = [*(command or default_command()), "batch", str(takes), "--out", str(out_dir)]
    if workers:
        argv += ["--workers", str(int(workers))]
    if scheduler:
        argv += ["--scheduler", str(scheduler)]
    if chunk_frames:
        argv += ["--chunk-frames", str(int(chunk_frames))]
    argv += option_args(settings or {}) + [str(a) for a in extra_args]
    log = open(out_dir / "batch.log", "ab")
    try:
        return subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env=command_environment())
    finally:
        log.close()


def takes_toml(takes):
    """[[take]] tables as TOML text (strings, whole numbers, numbers and booleans)."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return json.dumps(str(v))  # a JSON string is a TOML basic string

    lines = []
    for take in takes:
        lines.append("[[take]]")
        lines += [f"{k} = {value(v)}" for k, v in take.items() if v is not None]
        lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------- the command
def option_args(choices):
    """Tracking options as command-line arguments (None left out)."""
    out = []
    for name in CHOICE_NAMES:
        v = choices.get(name)
        if v is None:
            continue
        if isinstance(v, bool) and name == "refine":
            v = "icp" if v else "none"
        out += [f"--{name}", str(v)]
    return out


def _path_mapper(pairs):
    maps = []
    for pair in pairs:
        here, sep, there = pair.partition("=")
        if not sep or not here:
            from ..core.errors import InputError

            raise InputError(f"--path-map {pair!r}: give HERE=THERE (a path prefix here and on the workers)")
        maps.append((str(Path(here).resolve()), there))

    def mapped(path):
        text = str(Path(path).resolve())
        for here, there in maps:
            if text == here or text.startswith(here.rstrip("/\\") + os.sep):
                return there + text[len(here):].replace(os.sep, "/")
        return text
    return mapped


def check_rigs(takes):
    """Every take's subject opens and holds a rig the tracker can use; an InputError naming the take if not."""
    from ..addon.scene_bridge import body_from_blender, find_armature
    from ..core.batch.takes import TakeListError
    from .cmd_track import open_subject
    from .failures import USER_ERRORS

    checked = {}
    for take in takes:
        for name in take.armatures or [take.armature]:
            key = (str(take.scene.resolve()), name)
            if key not in checked:
                try:
                    scene = open_subject(take.scene)
                    armature = find_armature(scene, name)
                    body_from_blender(armature, None, scene)
                    checked[key] = None
                except USER_ERRORS as exc:
                    checked[key] = str(exc)
                except SystemExit as exc:
                    checked[key] = str(exc)
            if checked[key] is not None:
                raise TakeListError(f"take {take.name!r}: subject {take.scene}: {checked[key]}")
        if take.several:
            from .cast_session import CastError, cast_folders

            try:
                cast_folders(list(take.armatures))
            except CastError as exc:
                raise TakeListError(f"take {take.name!r}: {exc}") from None


class TakeRun:
    """One take in the batch: its chunks' folders and futures, its stitch, its state. `seeds`: the seed pass's files,
    one per actor (core/batch/seed.py)."""

    def __init__(self, take, plan, folders, seeds):
        self.take, self.plan, self.folders, self.seeds = take, plan, folders, list(seeds)
        self.futures = {}  # chunk index -> future
        self.attempts = {}  # chunk index -> runs that ended with a failure that is not the user's
        self.seed_future = None  # the seed pass (core/batch/seed.py), before the chunks after the first
        self.state = "queued"
        self.error = None
        self.stitch = None  # the stitch's Popen
        self.stitch_log = None

    @property
    def chunks_done(self):
        return sum(f.done for f in self.folders)

    @property
    def seeded(self):
        return all(path.is_file() for path in self.seeds)

    def frames_done(self):
        done = 0
        for c, f in zip(self.plan, self.folders):
            if f.done:
                done += c.track[1] - c.track[0] + 1
            else:
                done += _partial_frames(f.path)
        return done

    @property
    def frames_total(self):
        return sum(c.track[1] - c.track[0] + 1 for c in self.plan)

    def fail(self, reason):
        self.state, self.error = "failed", f"take {self.take.name!r}: {reason}"
        for future in [*self.futures.values(), self.seed_future]:
            if future is not None:
                future.cancel()
        self.futures.clear()
        self.seed_future = None


def _partial_frames(path):
    """Frames solved so far by an unfinished chunk (its partial folders' report.json)."""
    return max((frames_solved(partial) for partial in path.parent.glob(f".{path.name}.partial-*")), default=0)


class Batch:
    def __init__(self, args, takes, runs, chunks_root):
        self.args, self.takes, self.runs, self.chunks_root = args, takes, runs, chunks_root
        self.started = time.time()
        self.frames_at_start = sum(r.frames_done() for r in runs)
        self.state, self.error = "running", None
        self.local_command = default_command()
        self.worker_command = shlex.split(args.worker_command) if args.worker_command else self.local_command
        self.mapped = _path_mapper(args.path_map) if args.scheduler else (lambda p: str(Path(p).resolve()))
        self._printed = (None, 0.0)

    # ---- command lines
    def _take_args(self, run, mapped):
        take = run.take
        argv = ["--scene", mapped(take.scene), "--capture", mapped(take.capture), "--take", take.name,
                "--chunks", mapped(self.chunks_root)]
        for name in take.names:
            argv += ["--armature", name] if name else []
        if take.actor is not None:
            argv += ["--actor", mapped(take.actor)]
        for name, path in take.fitted.items():  # several actors: each one's fit, named
            argv += ["--actor", f"{name}={mapped(path)}"]
        return argv + option_args(take.choices)

    def chunk_argv(self, run, chunk):
        return [*self.worker_command, "track-chunk", *self._take_args(run, self.mapped),
                "--frames", f"{chunk.track[0]}-{chunk.track[1]}", "--stop-with-parent"]

    def _plan_args(self, run):
        a = self.args
        return ["--frames", f"{run.take.frames[0]}-{run.take.frames[1]}", "--chunk-frames", str(a.chunk_frames),
                "--warmup", str(a.warmup), "--overlap", str(a.overlap)]

    def seed_argv(self, run):
        return [*self.worker_command, "seed-chunks", *self._take_args(run, self.mapped), *self._plan_args(run)]

    def stitch_argv(self, run):
        a = self.args
        argv = [*self.local_command, "stitch", *self._take_args(run, lambda p: str(Path(p).resolve())),
                *self._plan_args(run), "--out", str(a.out / run.take.name), "--smooth", str(a.smooth)]
        argv += foot_lock_args(a.foot_lock, a.foot_lock_speed)
        return argv + (["--no-export"] if a.no_export else []) + (["--no-overlays"] if a.no_overlays else [])

    def stitch_signature(self, run):
        """What a take's stitch is made of: its command's words after the interpreter and each chunk's record. A
        rerun whose signature equals the one saved beside the take's result skips the stitch."""
        argv = self.stitch_argv(run)[len(self.local_command):]
        chunks = [hashlib.sha256((f.path / "chunk.json").read_bytes()).hexdigest() for f in run.folders]
        return {"argv": argv, "chunks": chunks}

    # ---- the loop
    def _submit_chunks(self, runner, run, first_only=False):
        for chunk, folder in zip(run.plan, run.folders):
            if not folder.done and chunk.index not in run.futures and (chunk.index == 0 or not first_only):
                # exit codes read here (_poll_chunks): a user's error is not worth running again, a crash is
                run.futures[chunk.index] = runner.submit(f"{run.take.name}-{chunk.name}", self.chunk_argv(run, chunk),
                                                         check=False)

    def run(self, runner):
        for run in self.runs:
            if run.state == "failed":  # before anything ran (its actor calibration)
                continue
            later = [f for f in run.folders[1:] if not f.done]
            if later and not run.seeded:  # the chunks after the first start where the seed pass says
                run.seed_future = runner.submit(f"{run.take.name}-seeds", self.seed_argv(run))
            self._submit_chunks(runner, run, first_only=run.seed_future is not None)
            run.state = "running" if run.futures or run.seed_future else "queued"
        while True:
            if cancel_requested(self.args.out):
                self.cancel()
                return EXIT_CANCELLED
            for run in self.runs:
                self._poll_seeds(runner, run)
                self._poll_chunks(runner, run)
            self._poll_stitches()
            self.report()
            if all(r.state in ("done", "failed") for r in self.runs):
                break
            time.sleep(POLL_SECONDS)
        self.state = "done"
        self.report(force=True)
        failed = [r for r in self.runs if r.state == "failed"]
        for r in failed:
            print(f"markerless_mocap batch: {r.error}", file=sys.stderr)
        done = [r for r in self.runs if r.state == "done"]
        print(f"batch: {len(done)} of {len(self.runs)} takes done in {time.time() - self.started:.0f} s -> "
              f"{self.args.out}", file=sys.stderr)
        return EXIT_SOME_FAILED if failed else 0

    def _poll_seeds(self, runner, run):
        from ..core.batch.cluster import failure_text
        from ..core.batch.seed import find_seed

        future = run.seed_future
        if future is None:
            return
        if future.status == "pending":  # chunks whose first frame the pass has reached begin now
            for chunk, folder in zip(run.plan, run.folders):
                if chunk.index and chunk.index not in run.futures and not folder.done:
                    if any(find_seed(self.chunks_root, run.take.name, folder.key, chunk.track[0], part) is None
                           for part in run.take.actor_folders):
                        break
                    run.futures[chunk.index] = runner.submit(f"{run.take.name}-{chunk.name}",
                                                             self.chunk_argv(run, chunk))
            return
        run.seed_future = None
        if future.status in ("finished", "lost") and run.seeded:
            self._submit_chunks(runner, run)
            return
        try:
            reason = failure_text(future.exception(timeout=5)) if future.status == "error" else \
                f"it ended without writing {run.seeds[-1]}" if future.status == "finished" else future.status
        except Exception as exc:  # noqa: BLE001  (the reason is reported, whatever it is)
            reason = f"{type(exc).__name__}: {exc}"
        run.fail(f"seed pass: {reason}")

    def _poll_chunks(self, runner, run):
        from ..core.batch.cluster import failure_text

        for index, future in list(run.futures.items()):
            status = future.status
            if status == "lost" and run.folders[index].done:  # its worker went after the chunk was written
                status = "finished"
            if status == "finished":
                del run.futures[index]
                ended = future.result(timeout=5) if future.status == "finished" else None
                code = getattr(ended, "returncode", 0)
                if code == EXIT_USER_ERROR:  # the footage, the rig, the settings: the same again would fail
                    run.fail(f"chunk {run.plan[index].name}: {failure_text(ended)}")
                    return
                if code != 0:
                    run.attempts[index] = run.attempts.get(index, 0) + 1
                    if run.attempts[index] > runner.retries:
                        run.fail(f"chunk {run.plan[index].name}: {failure_text(ended)} (after {run.attempts[index]} "
                                 "runs)")
                        return
                    chunk = run.plan[index]
                    run.futures[index] = runner.submit(f"{run.take.name}-{chunk.name}", self.chunk_argv(run, chunk),
                                                       check=False)
                    continue
                if not run.folders[index].done:
                    run.fail(f"chunk {run.plan[index].name}: its command ended without writing "
                             f"{run.folders[index].path} (is the chunk folder on storage the workers share?)")
                    return
            elif status in ("error", "cancelled", "lost"):
                try:
                    reason = failure_text(future.exception(timeout=5)) if status == "error" else status
                except Exception as exc:  # noqa: BLE001  (the reason is reported, whatever it is)
                    reason = f"{type(exc).__name__}: {exc}"
                run.fail(f"chunk {run.plan[index].name}: {reason}")
                return
        if run.state in ("queued", "running") and not run.futures and run.seed_future is None \
                and run.chunks_done == len(run.plan):
            run.state = "waiting"  # for its stitch

    def _poll_stitches(self):
        running = [r for r in self.runs if r.state == "stitching"]
        for run in running:
            code = run.stitch.poll()
            if code is None:
                continue
            run.stitch_log.close()
            if code == 0:
                run.state = "done"
                write_json(self.args.out / run.take.name / STITCHED_FILE, self.stitch_signature(run))
                self._say_views_without_landmarks(run)
            else:
                text = Path(run.stitch_log.name).read_text(errors="replace").splitlines()
                mine = [line for line in text if line.startswith("markerless_mocap")] or text[-1:]
                run.fail(f"stitch: {mine[-1] if mine else f'exit code {code}'} (log: {run.stitch_log.name})")
        if any(r.state == "stitching" for r in self.runs):
            return  # one stitch at a time: each reads the footage for its overlays
        for run in [r for r in self.runs if r.state == "waiting"]:
            if self._stitched_already(run):   # the same chunks and settings as the result there: nothing to do
                run.state = "done"
                print(f"batch: take {run.take.name!r}: already stitched from these chunks with these settings; "
                      f"{self.args.out / run.take.name} kept", file=sys.stderr, flush=True)
        waiting = [r for r in self.runs if r.state == "waiting"]
        if waiting:
            run = waiting[0]
            out = self.args.out / run.take.name
            out.mkdir(parents=True, exist_ok=True)
            run.stitch_log = open(out / "stitch.log", "w")
            run.stitch = subprocess.Popen(self.stitch_argv(run), stdout=run.stitch_log, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, env=command_environment())
            run.state = "stitching"

    def _say_views_without_landmarks(self, run):
        """The stitched take's end-of-take line about views whose landmarks were left out, as `track` prints it."""
        from ..core.results.views_without_landmarks import views_without_landmarks_in_result

        said = views_without_landmarks_in_result(self.args.out / run.take.name)
        if said:
            print(f"batch: take {run.take.name!r}: {said}", file=sys.stderr, flush=True)

    def _stitched_already(self, run):
        out = self.args.out / run.take.name
        try:
            saved = json.loads((out / STITCHED_FILE).read_text())
        except (OSError, ValueError):
            return False
        return (out / "report.json").is_file() \
            and all((actor_result_folder(out, part) / "joints.npz").is_file() for part in run.take.actor_folders) \
            and saved == self.stitch_signature(run)

    def cancel(self):
        for run in self.runs:
            for future in run.futures.values():
                future.cancel()
            if run.stitch is not None and run.stitch.poll() is None:
                run.stitch.terminate()
            if run.state not in ("done", "failed"):
                run.state, run.error = "failed", f"take {run.take.name!r}: cancelled"
        self.state = "cancelled"
        self.report(force=True)
        print("markerless_mocap batch: cancelled; finished chunks are kept (run the batch again to go on)",
              file=sys.stderr)

    # ---- progress
    def progress(self):
        done = [r.frames_done() for r in self.runs]
        total = [r.frames_total for r in self.runs]
        new = sum(done) - self.frames_at_start
        elapsed = time.time() - self.started
        left = sum(total) - sum(done)
        seconds_left = 0.0 if left == 0 else (left * elapsed / new if new > 0 else None)
        return {"state": self.state, "started": self.started, "error": self.error,
                "total": {"chunks_done": sum(r.chunks_done for r in self.runs),
                          "chunks_total": sum(len(r.plan) for r in self.runs), "frames_done": sum(done),
                          "frames_total": sum(total), "seconds_left": seconds_left},
                "takes": [{"name": r.take.name, "state": "stitching" if r.state == "waiting" else r.state,
                           "chunks_done": r.chunks_done, "chunks_total": len(r.plan), "frames": list(r.take.frames),
                           "result": str(self.args.out / r.take.name) if r.state == "done" else None,
                           "error": r.error} for r in self.runs]}

    def report(self, force=False):
        progress = self.progress()
        write_progress(self.args.out, progress)
        lines = progress_lines(progress)
        key = tuple((t["state"], t["chunks_done"]) for t in progress["takes"])
        now = time.time()
        if sys.stderr.isatty():
            if self._printed[0] is not None:
                sys.stderr.write(f"\x1b[{self._printed[0]}F\x1b[J")
            sys.stderr.write("\n".join(lines) + "\n")
            sys.stderr.flush()
            self._printed = (len(lines), now)
        elif force or key != self._printed[0] or now - self._printed[1] >= PRINT_SECONDS:
            print("\n".join(lines), file=sys.stderr, flush=True)
            self._printed = (key, now)


def calibrate_takes(takes, out, runner, command, mapped, chunks_root):
    """Fit the actors of the takes that calibrate on their first frames (a take without an `actor`: with `calibrate =
    true`; by default when it has at least DEFAULT_FRAMES frames, or for an actor whose lengths were measured): one
    `calibrate` command per actor (each of a take of several, as `track` fits them), all submitted to the cluster at
    once before any chunk is planned (the chunks track with the fit), written on the shared storage
    (CHUNKS/<take>/actor/, or CHUNKS/<take>/actors/<armature>/) and kept beside the take's result; a rerun reuses a
    fit already there. Returns {take name: reason} for the takes whose fit failed, or None when the batch was
    cancelled meanwhile."""
    from ..core.actor.frames import DEFAULT_FRAMES
    from ..core.batch.cluster import failure_text

    pending = {}
    for take in takes:
        if take.actor is not None or take.calibrate is False:
            continue
        first, last = take.frames[0], min(take.frames[1], take.frames[0] + DEFAULT_FRAMES - 1)
        for name, part in zip(take.names, take.actor_folders):
            if take.calibrate is None and take.n_frames < DEFAULT_FRAMES and not take.measured_of(name):
                continue  # as `track`: a short take keeps the rig, unless the actor's lengths were measured
            shared = chunks_root / take.name / ("actor" if part is None else Path(ACTORS_FOLDER) / part)
            fit, result = shared / "actor.json", actor_result_folder(out / take.name, part)
            if fit.is_file():
                _keep_fit(take, name, fit, result)
                continue
            argv = [*command, "calibrate", "--scene", mapped(take.scene), "--capture", mapped(take.capture),
                    "--out", mapped(shared), "--frames", f"{first}-{last}"]
            argv += (["--armature", name] if name else []) + option_args(take.choices)
            for length in take.measured_of(name):  # as `calibrate --measured` takes them
                argv += ["--measured", length]
            whose = f" {name}" if take.several else ""
            print(f"batch: take {take.name!r}: calibrating the actor{whose} on frames {first}-{last}",
                  file=sys.stderr, flush=True)
            task = runner.submit(f"{take.name}-calibrate{whose.replace(' ', '-')}", argv, check=False)
            pending[(take.name, name)] = (take, whose, fit, result, task)
    failed = {}
    while pending:
        if cancel_requested(out):
            return None
        for (take_name, name), (take, whose, fit, result, future) in list(pending.items()):
            if future.status == "pending":
                continue
            del pending[(take_name, name)]
            try:
                done = future.result(timeout=5)
            except Exception as exc:  # noqa: BLE001  (the worker's failure is the take's reason)
                done = exc
            if getattr(done, "returncode", 1) != 0 or not fit.is_file():
                failed.setdefault(take_name, f"actor{whose} calibration: {failure_text(done)}")
                continue
            print(f"batch: take {take_name!r}: actor{whose} calibrated", file=sys.stderr, flush=True)
            _keep_fit(take, name, fit, result)
        if pending:
            time.sleep(POLL_SECONDS)
    for take in takes:
        if take.name in failed:
            take.actor, take.fitted = None, {}
    return failed


def _keep_fit(take, name, fit, result):
    """Track the take's actor `name` with the fit, and keep it beside that actor's result from now on (`result`:
    DIR/<take>/, or its actors/<armature>/), where Blender's Track reads it to key the take (the stitch writes it there
    too)."""
    from ..core.actor.actor_file import load_actor, write_actor

    if take.several:
        take.fitted[name] = fit
    else:
        take.actor = fit
    result.mkdir(parents=True, exist_ok=True)
    write_actor(result / "actor.json", load_actor(fit))


def take_key(take):
    """The take's chunk key, as its chunk commands compute it from their arguments (track-chunk's take_inputs)."""
    from ..core.actor.actor_file import load_actor
    from ..core.batch.chunk_folder import chunk_key

    settings = take.settings().to_dict()
    if not take.several:
        actor = load_actor(take.actor) if take.actor is not None else None
        return chunk_key(settings, take.scene, take.armature, actor, take.capture)
    fits = [load_actor(take.fitted[n]) if n in take.fitted else None for n in take.names]
    return chunk_key(settings, take.scene, take.names, fits, take.capture)


def _choices_of(args):
    return {name: getattr(args, name) for name in CHOICE_NAMES if getattr(args, name) is not None}


def run(args):
    from ..core.batch.chunk_folder import CHUNKS_FOLDER, ChunkFolder
    from ..core.batch.cluster import ChunkRunner, chunk_environment
    from ..core.batch.plan import plan_chunks
    from ..core.batch.seed import seeds_path
    from ..core.batch.takes import TakeListError, read_take_list
    from .failures import USER_ERRORS, cli_failure

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / CANCEL_FILE).unlink(missing_ok=True)
    blank = {"state": "planning", "started": time.time(), "error": None, "takes": [],
             "total": {"chunks_done": 0, "chunks_total": 0, "frames_done": 0, "frames_total": 0, "seconds_left": None}}
    write_progress(out, blank)
    chunks_root = (args.chunks or out / CHUNKS_FOLDER).resolve()
    try:
        if args.workers is not None and args.workers < 1:
            from ..core.errors import InputError

            raise InputError(f"--workers {args.workers}: at least one")
        takes = read_take_list(args.takes, defaults=_choices_of(args), scene=args.scene, armature=args.armature)
        check_rigs(takes)
        if args.no_calibrate:
            for take in takes:
                take.calibrate = take.calibrate or False  # an explicit `calibrate = true` stands
                if take.measured and take.calibrate is False:
                    raise TakeListError(f"take {take.name!r}: measured lengths are for fitting the actor, but "
                                        "--no-calibrate tracks it with the rig: give it `calibrate = true`, or leave "
                                        "its measured lengths out")
        plans = {}
        for take in takes:  # every take's plan checked before anything runs
            try:
                plans[take.name] = plan_chunks(take.frames[0], take.frames[1], args.chunk_frames, args.warmup,
                                               args.overlap)
            except USER_ERRORS as exc:
                raise type(exc)(f"take {take.name!r}: {exc}") from None
    except USER_ERRORS as exc:
        write_progress(out, {**blank, "state": "failed", "error": str(exc)})
        return cli_failure("batch", exc)
    workers = args.workers
    env = None
    if args.scheduler is None:
        from ..core.batch.cluster import default_workers

        workers = workers or default_workers()
        threads = args.threads_per_chunk or max(1, (os.cpu_count() or 2) // workers)
        env = chunk_environment(threads, command_environment())
    batch = Batch(args, takes, [], chunks_root)
    previous = signal.signal(signal.SIGTERM, lambda *_: request_cancel(out))  # stop as a cancel does
    try:
        with ChunkRunner(workers=workers, scheduler=args.scheduler, retries=args.retries, env=env) as runner:
            uncalibrated = calibrate_takes(takes, out, runner, batch.worker_command, batch.mapped, chunks_root)
            if uncalibrated is None:
                batch.cancel()
                return EXIT_CANCELLED
            for take in takes:
                plan = plans[take.name]
                key = take_key(take)
                batch.runs.append(TakeRun(take, plan, [ChunkFolder(chunks_root, take.name, c.track, key) for c in plan],
                                          [seeds_path(chunks_root, take.name, *take.frames, key, part)
                                           for part in take.actor_folders]))
                if take.name in uncalibrated:  # fails alone; the other takes go on
                    batch.runs[-1].fail(uncalibrated[take.name])
            batch.frames_at_start = sum(r.frames_done() for r in batch.runs)
            return batch.run(runner)
    except KeyboardInterrupt:
        batch.cancel()
        return EXIT_CANCELLED
    except Exception as exc:
        batch.state, batch.error = "failed", f"{type(exc).__name__}: {exc}"
        batch.report(force=True)
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["default_command", "launch_batch", "read_progress", "request_cancel"]
