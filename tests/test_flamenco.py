"""The Flamenco job type (tools/flamenco/markerless_mocap.js), run under Node with a stand-in for Flamenco's `author`.

Its plans must equal the Python planner's (`plan-chunks --json`) so a take sent to Flamenco and one sent to `batch`
share their chunk folders; the command lines its tasks run must parse with the real command line, naming the
chunk's frames and the job's settings; the stitch task must wait for every chunk task. Node is Debian's `nodejs`
(the test is skipped, saying so, where it is not installed).
"""
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from markerless_mocap.core.batch.plan import (DEFAULT_CHUNK_FRAMES, DEFAULT_OVERLAP, DEFAULT_WARMUP, PlanError,
                                              plan_chunks, plan_to_json)
from markerless_mocap.core.batch.chunk_folder import check_take_name
from markerless_mocap.core.errors import InputError
from markerless_mocap.core.tracking.options import OPTIONS
from markerless_mocap.core.tracking.smoothing import DEFAULT_CUTOFF_HZ
from markerless_mocap.operators import cli
from markerless_mocap.operators.cmd_track import settings_from_args

REPO = Path(__file__).resolve().parents[1]
JOB_TEST = REPO / "tools" / "flamenco" / "plan.test.js"
NODE = shutil.which("node") or shutil.which("nodejs")
pytestmark = pytest.mark.skipif(NODE is None, reason="Node.js is not installed (Debian: apt-get install nodejs): "
                                                     "the Flamenco job type's planning is not tested")

# (first, last, chunk frames, warm-up, overlap): long and short takes, chunk sizes that divide the take and that do
# not, no warm-up or overlap, a warm-up reaching before the take's start; the last ones are refused.
PLAN_CASES = [
    (0, 599, 300, 10, 5), (0, 35999, 300, 10, 5), (0, 36000, 300, 10, 5), (17, 1016, 250, 12, 6),
    (0, 0, 300, 10, 5), (5, 9, 300, 10, 5), (0, 99, 7, 3, 2), (0, 99, 1, 0, 0), (0, 99, 10, 40, 5),
    (100, 1099, 333, 0, 0), (0, 2, 2, 10, 1),
    (0, 99, 8, 10, 5), (10, 5, 300, 10, 5), (-1, 5, 300, 10, 5), (0, 99, 0, 10, 5),
]
TAKE_NAMES = ["walk01", "day2.take-07", "A", "9_x", "_chunks", ".hidden", "-x", "my take", "tåke", "a/b", "x" * 80]
RUNNER_PREFIX = {"blender": ("{blender}", ["--background", "--command", "markerless_mocap"]),
                 "python": ("{mocap_python}", ["-m", "markerless_mocap"])}
JOBS = [
    {"blendfile": "/farm/subjects/anna.blend", "capture": "/farm/captures/walk01", "output_root": "/farm/results",
     "frames": "0-999"},
    {"blendfile": "/farm/subjects/anna.blend", "capture": "/farm/captures/long/", "output_root": "/farm/results",
     "frames": "120-4119", "take": "day2-long", "chunk_frames": 700, "warmup": 20, "overlap": 8, "smooth": 0,
     "preset": "preview", "particles": 40, "iterations": 3, "seed": 2, "refine": "none", "backend": "fast",
     "armature": "Rig", "actor": "/farm/actors/anna.json", "runner": "python"},
    {"blendfile": "/farm/s.blend", "capture": "/farm/c", "output_root": "/farm/out", "frames": "7"},
]
# several actors: each one's build fitted, then the chunks and the stitch with every armature
CAST_JOB = {"blendfile": "/farm/duet.blend", "capture": "/farm/captures/duet", "output_root": "/farm/results",
            "frames": "0-899", "armature": "Lead, Partner", "seed": 1, "smooth": 6, "runner": "python"}


def _python_plan_json(case, capsys):
    """The plan as `plan-chunks --json` prints it, or the planner's refusal."""
    first, last, k, w, o = case
    try:
        plan_chunks(first, last, k, w, o)
    except PlanError as exc:
        return None, str(exc)
    assert cli.main(["plan-chunks", "--frames", f"{first}-{last}", "--chunk-frames", str(k), "--warmup", str(w),
                     "--overlap", str(o), "--json"]) == 0
    return json.loads(capsys.readouterr().out), None


def _run_node(tmp_path, cases):
    cases_file, dump = tmp_path / "cases.json", tmp_path / "compiled.json"
    cases_file.write_text(json.dumps(cases))
    proc = subprocess.run([NODE, "--test", str(JOB_TEST)], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, MOCAP_FLAMENCO_CASES=str(cases_file), MOCAP_FLAMENCO_DUMP=str(dump)))
    return proc, (json.loads(dump.read_text()) if dump.is_file() else None)


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    """Node's test run against the Python plans and options, and the jobs it compiled."""
    tmp_path = tmp_path_factory.mktemp("flamenco")
    plans = []
    for case in PLAN_CASES:
        first, last, k, w, o = case
        try:
            plan, error = plan_to_json(first, last, k, w, o), None
        except PlanError as exc:
            plan, error = None, str(exc)
        plans.append({"args": list(case), "plan": plan, "error": error})
    take_names = []
    for name in TAKE_NAMES:
        try:
            take_names.append({"name": name, "ok": check_take_name(name) == name})
        except InputError:
            take_names.append({"name": name, "ok": False})
    cases = {"plans": plans, "jobs": JOBS + [CAST_JOB], "take_names": take_names,
             "options": {name: {"values": list(o.values), "default": o.default} for name, o in OPTIONS.items()},
             "defaults": {"chunk_frames": DEFAULT_CHUNK_FRAMES, "warmup": DEFAULT_WARMUP, "overlap": DEFAULT_OVERLAP,
                          "smooth": DEFAULT_CUTOFF_HZ}}
    proc, jobs = _run_node(tmp_path, cases)
    return {"proc": proc, "jobs": jobs, "plans": plans}


def test_node_tests_pass_with_the_python_plans(compiled):
    proc = compiled["proc"]
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    out = proc.stdout
    for name in ("the plans equal the Python planner's", "settings offer the Python options' values and defaults",
                 "jobs compile (written for the Python side)",
                 "take names are refused where the Python side refuses them",
                 "one exec task per chunk, and a stitch task that depends on every one of them"):
        assert re.search(rf"^ok \d+ - {re.escape(name)}$", out, re.MULTILINE), \
            f"{name!r} did not pass:\n{out[-3000:]}"
    assert "# fail 0" in out and "# skipped 0" in out
    assert sum(p["error"] is not None for p in compiled["plans"]) == 4  # the refused cases were compared too


def test_the_plan_cases_come_from_the_plan_chunks_command(compiled, capsys):
    """What Node compared with is what `plan-chunks --json` prints (in process, and once as a real process)."""
    for case, sent in zip(PLAN_CASES, compiled["plans"]):
        printed, error = _python_plan_json(case, capsys)
        assert printed == sent["plan"] and (error is None) == (sent["error"] is None), case
    proc = subprocess.run([sys.executable, "-m", "markerless_mocap", "plan-chunks", "--frames", "0-35999",
                           "--json"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    printed = json.loads(proc.stdout)
    assert (printed["chunk_frames"], printed["warmup"], printed["overlap"]) == (
        DEFAULT_CHUNK_FRAMES, DEFAULT_WARMUP, DEFAULT_OVERLAP)
    assert printed == compiled["plans"][1]["plan"]


def _parse(task):
    """The task's one exec command, parsed by the real command line: (runner, argparse namespace)."""
    assert [c["name"] for c in task["commands"]] == ["exec"], task
    params = task["commands"][0]["parameters"]
    runner = next(r for r, (exe, _) in RUNNER_PREFIX.items() if exe == params["exe"])
    prefix = RUNNER_PREFIX[runner][1]
    assert params["args"][:len(prefix)] == prefix, params
    assert all(isinstance(a, str) for a in params["args"]), params  # exec passes strings, no shell
    return runner, cli.build_parser().parse_args(params["args"][len(prefix):])


@pytest.mark.parametrize("index", range(len(JOBS)))
def test_each_task_runs_the_chunk_command_the_python_plan_names(compiled, index):
    settings, tasks = JOBS[index], compiled["jobs"][index]
    first, _, last = settings["frames"].partition("-")
    first, last = int(first), int(last or first)
    k, w, o = (settings.get(key, default) for key, default in
               (("chunk_frames", DEFAULT_CHUNK_FRAMES), ("warmup", DEFAULT_WARMUP), ("overlap", DEFAULT_OVERLAP)))
    plan = plan_chunks(first, last, k, w, o)
    take = settings.get("take") or Path(settings["capture"]).name
    out_root = Path(settings["output_root"])
    seeds = [t for t in tasks if t["name"] == f"seeds-{take}"]
    chunk_tasks, stitch = tasks[len(seeds):-1], tasks[-1]
    assert len(chunk_tasks) == len(plan) and len(seeds) == (len(plan) > 1)
    for task in seeds:  # where the chunks after the first start (core/batch/seed.py), planned as the chunks are
        _, args = _parse(task)
        assert (args.command, args.frames, args.take, args.chunks) == (
            "seed-chunks", f"{first}-{last}", take, out_root / "_chunks")
        assert (args.chunk_frames, args.warmup, args.overlap) == (k, w, o) and task["depends_on"] == []

    chosen = {name: settings.get(name) for name in OPTIONS if settings.get(name) is not None}
    parsed_settings = []
    for chunk, task in zip(plan, chunk_tasks):
        assert task["type"] == "mocap" and task["depends_on"] == ([] if chunk.index == 0 else [f"seeds-{take}"])
        assert task["name"] == f"track-{take}-{chunk.name}"
        runner, args = _parse(task)
        assert runner == settings.get("runner", "blender")
        assert args.command == "track-chunk"
        assert args.frames == f"{chunk.track[0]}-{chunk.track[1]}"
        assert (args.scene, args.capture, args.take, args.chunks) == (
            Path(settings["blendfile"]), Path(settings["capture"]), take, out_root / "_chunks")
        assert args.armature == ([settings["armature"]] if "armature" in settings else None)
        assert args.actor == ([settings["actor"]] if "actor" in settings else None)
        for name, value in chosen.items():
            assert getattr(args, name) == value, name
        parsed_settings.append(settings_from_args(args).to_dict())

    assert stitch["name"] == f"stitch-{take}" and stitch["type"] == "mocap"
    assert sorted(stitch["depends_on"]) == sorted(t["name"] for t in chunk_tasks)
    _, args = _parse(stitch)
    assert args.command == "stitch"
    assert args.frames == f"{first}-{last}"
    assert (args.chunk_frames, args.warmup, args.overlap) == (k, w, o)
    assert args.out == out_root / take and args.chunks == out_root / "_chunks"
    assert args.smooth == settings.get("smooth", DEFAULT_CUTOFF_HZ)
    assert (args.scene, args.capture, args.take, args.armature) == (
        Path(settings["blendfile"]), Path(settings["capture"]), take,
        [settings["armature"]] if "armature" in settings else None)
    # the stitch finds the chunk folders by the same settings (their folder names hash them)
    assert all(s == settings_from_args(args).to_dict() for s in parsed_settings)


def test_a_job_of_several_actors_fits_each_build_then_tracks_every_actor_in_each_chunk(compiled):
    """The commands parse with the real command line: each actor's `calibrate` writes where the chunk commands read
    it (--actor NAME=FILE), and every chunk command names every armature, as `batch` runs a take of several."""
    from markerless_mocap.core.actor.frames import DEFAULT_FRAMES
    from markerless_mocap.core.actor.per_actor import options_of

    tasks = compiled["jobs"][len(JOBS)]
    fits = {t["name"]: _parse(t)[1] for t in tasks if t["name"].startswith("calibrate-")}
    assert sorted(fits) == ["calibrate-duet-Lead", "calibrate-duet-Partner"]
    for name in ("Lead", "Partner"):
        args = fits[f"calibrate-duet-{name}"]
        assert (args.command, args.armature, args.frames) == ("calibrate", name, f"0-{DEFAULT_FRAMES - 1}")
        assert args.seed == 1
    tracked = [t for t in tasks if not t["name"].startswith("calibrate-")]
    assert [t["name"] for t in tracked][0] == "seeds-duet" and tracked[-1]["name"] == "stitch-duet"
    assert len(tracked) == len(plan_chunks(0, 899, DEFAULT_CHUNK_FRAMES, DEFAULT_WARMUP, DEFAULT_OVERLAP)) + 2
    for task in tracked:
        runner, args = _parse(task)
        assert runner == "python" and args.armature == ["Lead", "Partner"], task["name"]
        for name in ("Lead", "Partner"):  # the fit `calibrate` wrote, read as track-chunk reads it
            assert options_of(args, name)[0] == fits[f"calibrate-duet-{name}"].out / "actor.json"
    assert sorted(tracked[0]["depends_on"]) == sorted(fits)
