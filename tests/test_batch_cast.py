"""A batch take of several actors (`armature = ["Lead", "Partner"]`, operators/batch_cast.py): tracked whole by one
`track` on a worker beside a chunked take, its result folder the one `track` writes for several actors and equal to
it, a rerun that tracks nothing again, and an armature the subject lacks refused before anything runs.

The preview preset on the duet's frames 0-1, so the two runs compared are short."""
import json
import subprocess
import sys

import numpy as np
import pytest

from scene_helpers import cli_environment, scene_dir

DUET = scene_dir("duet")
WALK = scene_dir("walk")
OPTIONS = ["--preset", "preview", "--backend", "fast", "--no-overlays", "--no-export"]

pytestmark = pytest.mark.slow


def _takes(tmp_path, armatures='["Lead", "Partner"]'):
    path = tmp_path / "takes.toml"
    path.write_text(f'[[take]]\nname = "duet"\nscene = "{DUET / "subject.blend"}"\ncapture = "{DUET}"\n'
                    f'frames = "0-1"\narmature = {armatures}\n\n'
                    f'[[take]]\nname = "walk"\nscene = "{WALK / "subject.blend"}"\ncapture = "{WALK}"\n'
                    'frames = "0-11"\n')
    return path


def _run(*argv):
    return subprocess.run([sys.executable, "-m", "markerless_mocap", *map(str, argv)], capture_output=True,
                          text=True, env=cli_environment(), timeout=900)


def test_a_take_of_two_actors_runs_whole_beside_a_chunked_take_and_equals_track(tmp_path):
    out = tmp_path / "out"
    batch = ["batch", _takes(tmp_path), "--out", out, "--workers", "2", "--chunk-frames", "6", "--warmup", "3",
             "--overlap", "2", *OPTIONS]
    done = _run(*batch)
    assert done.returncode == 0, done.stderr[-3000:]
    progress = json.loads((out / "batch-progress.json").read_text())
    duet = next(t for t in progress["takes"] if t["name"] == "duet")
    assert (duet["state"], duet["chunks_done"], duet["chunks_total"]) == ("done", 1, 1)
    assert progress["total"]["frames_done"] == progress["total"]["frames_total"]
    report = json.loads((out / "duet" / "report.json").read_text())
    assert [a["armature"] for a in report["actors"]] == ["Lead", "Partner"]

    alone = tmp_path / "alone"
    one = _run("track", "--scene", DUET / "subject.blend", "--capture", DUET, "--out", alone, "--frames", "0-1",
               "--armature", "Lead", "--armature", "Partner", *OPTIONS)
    assert one.returncode == 0, one.stderr[-3000:]
    for name in ("Lead", "Partner"):  # the same command on a worker: the same poses, to rounding
        with np.load(out / "duet" / "actors" / name / "poses.npz") as a, \
                np.load(alone / "actors" / name / "poses.npz") as b:
            assert list(a["frames"]) == list(b["frames"]) == [0, 1]
            assert np.abs(a["poses"] - b["poses"]).max() < 1e-6, name

    (work,) = (out / "_chunks" / "duet").glob("cast-*")
    stamp = (work / "actors" / "Lead" / "checkpoint.npz").stat().st_mtime_ns
    again = _run(*batch)
    assert again.returncode == 0, again.stderr[-3000:]
    assert (work / "actors" / "Lead" / "checkpoint.npz").stat().st_mtime_ns == stamp  # nothing tracked again

    bad = _run("batch", _takes(tmp_path, '["Lead", "Nobody"]'), "--out", tmp_path / "bad", *OPTIONS)
    assert bad.returncode == 2
    assert "take 'duet': subject" in bad.stderr and "'Nobody'" in bad.stderr, bad.stderr[-2000:]


def test_track_stops_when_the_worker_that_started_it_is_gone_and_keeps_its_frames(monkeypatch, capsys):
    """`track --stop-with-parent` (the batch's cast takes): once its parent process has ended it stops before the
    next frame with EXIT_PARENT_GONE, the frames solved kept for --resume; without the option it goes on."""
    from types import SimpleNamespace

    from markerless_mocap.operators import cmd_track
    from markerless_mocap.operators.failures import EXIT_PARENT_GONE

    class Session:
        def __init__(self):
            self.n_done, self.n_total = 0, 5

        def solve_next(self):
            if self.n_done == self.n_total:
                return None
            self.n_done += 1
            return SimpleNamespace(frame=self.n_done - 1, seconds=0.1, energy=1.0)

        def key(self, est):
            pass

    for option, solved, code in ((True, 2, EXIT_PARENT_GONE), (False, 5, None)):
        parents = iter([100, 100, 100] + [1] * 10)  # the watch's start, then frames 0 and 1; re-parented after
        monkeypatch.setattr(cmd_track.os, "getppid", lambda parents=parents: next(parents))
        session = Session()
        assert cmd_track.solve_all(session, "OUT", stop_with_parent=option) == code
        assert session.n_done == solved
    assert "stopping with 2 frames solved and saved in OUT (run again with --resume)" in capsys.readouterr().err


def test_a_cast_takes_command_carries_its_actors_calibration_and_the_batchs_finishing(tmp_path):
    """The worker's `track` for a take of several actors: each armature, --resume and --stop-with-parent, whether to
    fit the builds and each actor's measured lengths, the take's options and the batch's smoothing and exports."""
    from argparse import Namespace

    from markerless_mocap.core.batch.takes import Take
    from markerless_mocap.operators.batch_cast import cast_argv

    take = Take("duet", DUET / "subject.blend", DUET, (5, 44), choices={"seed": 2}, calibrate=True,
                armatures=("Lead", "Partner"), measured=("Partner:height=1.62",))
    args = Namespace(smooth=6.0, foot_lock=False, foot_lock_speed=0.2, no_export=True, no_overlays=False)
    argv = cast_argv(["mm"], take, tmp_path / "w", str, args)
    assert argv[:2] == ["mm", "track"] and argv[argv.index("--frames") + 1] == "5-44"
    assert [argv[i + 1] for i, a in enumerate(argv) if a == "--armature"] == ["Lead", "Partner"]
    assert {"--resume", "--stop-with-parent", "--calibrate", "--no-foot-lock", "--no-export"} <= set(argv)
    assert argv[argv.index("--calibrate-measured") + 1] == "Partner:height=1.62"
    assert (argv[argv.index("--seed") + 1], argv[argv.index("--smooth") + 1]) == ("2", "6.0")
    assert "--no-overlays" not in argv
