"""A batch take of several actors (`armature = ["Lead", "Partner"]`): cut into chunks like one actor's take, each
chunk tracking the actors together (track-chunk with each --armature), the seed pass following them together, and
the stitch writing the layout `track` writes for several actors. A take that fits in one chunk equals `track`'s own
run; a rerun tracks nothing again; an armature the subject lacks is refused before anything runs.

The preview preset on the duet's first frames, so the runs compared are short."""
import json
import subprocess
import sys

import numpy as np
import pytest

from scene_helpers import cli_environment, scene_dir

DUET = scene_dir("duet")
OPTIONS = ["--preset", "preview", "--backend", "fast", "--no-overlays", "--no-export"]
ACTORS = ("Lead", "Partner")

pytestmark = pytest.mark.slow


def _takes(tmp_path, armatures='["Lead", "Partner"]'):
    path = tmp_path / "takes.toml"
    path.write_text(f'[[take]]\nname = "duet"\nscene = "{DUET / "subject.blend"}"\ncapture = "{DUET}"\n'
                    f'frames = "0-5"\narmature = {armatures}\n\n'
                    f'[[take]]\nname = "short"\nscene = "{DUET / "subject.blend"}"\ncapture = "{DUET}"\n'
                    f'frames = "6-7"\narmature = {armatures}\n')
    return path


def _run(*argv):
    return subprocess.run([sys.executable, "-m", "markerless_mocap", *map(str, argv)], capture_output=True,
                          text=True, env=cli_environment(), timeout=900)


def _poses(folder, file="poses.npz"):
    with np.load(folder / file) as data:
        return list(data["frames"]), data["poses"].copy()


def test_a_take_of_two_actors_is_tracked_in_chunks_and_stitched_per_actor(tmp_path):
    from markerless_mocap.core.batch.chunk_folder import ChunkFolder

    out = tmp_path / "out"
    batch = ["batch", _takes(tmp_path), "--out", out, "--workers", "2", "--chunk-frames", "3", "--warmup", "1",
             "--overlap", "1", *OPTIONS]
    done = _run(*batch)
    assert done.returncode == 0, done.stderr[-3000:]
    progress = json.loads((out / "batch-progress.json").read_text())
    takes = {t["name"]: t for t in progress["takes"]}
    assert (takes["duet"]["state"], takes["duet"]["chunks_done"], takes["duet"]["chunks_total"]) == ("done", 2, 2)
    assert (takes["short"]["chunks_done"], takes["short"]["chunks_total"]) == (1, 1)
    assert progress["total"]["frames_done"] == progress["total"]["frames_total"]
    report = json.loads((out / "duet" / "report.json").read_text())
    assert [a["armature"] for a in report["actors"]] == list(ACTORS)

    chunks = sorted(p for p in (out / "_chunks" / "duet").glob("0*") if p.is_dir())
    assert len(chunks) == 2
    info = json.loads((chunks[1] / "chunk.json").read_text())
    assert info["start"] == "seeds" and info["armature"] == list(ACTORS)  # each actor started where the pass found it
    assert len(list((out / "_chunks" / "duet").glob("seeds-*.npz"))) == 2  # one per actor
    key = chunks[0].name.split("_")[-1]
    folders = [ChunkFolder(out / "_chunks", "duet", track, key) for track in ((0, 3), (2, 5))]
    for name in ACTORS:
        frames, raw = _poses(out / "duet" / "actors" / name, "poses_raw.npz")
        assert frames == list(range(6))
        first, second = (f.estimates(name) for f in folders)
        for f in (0, 1, 2):  # kept from the first chunk, as it solved them
            assert np.abs(raw[f] - first[f].pose).max() < 1e-9, (name, f)
        for f in (4, 5):  # from the second, after the cross-fade at frame 3
            assert np.abs(raw[f] - second[f].pose).max() < 1e-9, (name, f)
        # the second chunk started on the same person: its hips at frame 2 near the first chunk's
        assert np.linalg.norm(second[2].joints[0] - first[2].joints[0]) < 0.15, name
        actor_report = json.loads((out / "duet" / "actors" / name / "report.json").read_text())
        assert actor_report["batch"]["overlaps"][0]["chunks"] == [0, 1]
        assert actor_report["batch"]["overlap_mean_joint_mm"] is not None

    alone = tmp_path / "alone"
    one = _run("track", "--scene", DUET / "subject.blend", "--capture", DUET, "--out", alone, "--frames", "6-7",
               "--armature", "Lead", "--armature", "Partner", *OPTIONS)
    assert one.returncode == 0, one.stderr[-3000:]
    for name in ACTORS:  # a take in one chunk: the poses `track` gives, to rounding
        frames, batch_poses = _poses(out / "short" / "actors" / name)
        track_frames, track_poses = _poses(alone / "actors" / name)
        assert frames == track_frames == [6, 7]
        assert np.abs(batch_poses - track_poses).max() < 1e-6, name

    stamps = [(c / "chunk.json").stat().st_mtime_ns for c in chunks]
    again = _run(*batch)
    assert again.returncode == 0, again.stderr[-3000:]
    assert [(c / "chunk.json").stat().st_mtime_ns for c in chunks] == stamps  # nothing tracked again
    assert "already stitched" in again.stderr

    bad = _run("batch", _takes(tmp_path, '["Lead", "Nobody"]'), "--out", tmp_path / "bad", *OPTIONS)
    assert bad.returncode == 2
    assert "take 'duet': subject" in bad.stderr and "'Nobody'" in bad.stderr, bad.stderr[-2000:]


def test_track_stops_when_the_worker_that_started_it_is_gone_and_keeps_its_frames(monkeypatch, capsys):
    """`track --stop-with-parent` (a farm's task): once its parent process has ended it stops before the next frame
    with EXIT_PARENT_GONE, the frames solved kept for --resume; without the option it goes on."""
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


def test_a_cast_takes_chunk_commands_name_each_actor_and_its_fit(tmp_path):
    """The chunk commands of a take of several actors: each --armature, each actor's fitted build as
    --actor NAME=FILE, the take's options; and the take's key is the one track-chunk computes from them."""
    from argparse import Namespace

    from markerless_mocap.core.actor.actor_file import FORMAT, write_actor
    from markerless_mocap.core.batch.plan import plan_chunks
    from markerless_mocap.core.batch.takes import Take
    from markerless_mocap.operators import cmd_batch, cmd_track_chunk
    from markerless_mocap.operators.cli import build_parser

    fit = tmp_path / "Partner.json"
    write_actor(fit, {"format": FORMAT, "lengths_m": {}, "factors": {}, "overall": 1.02})
    take = Take("duet", DUET / "subject.blend", DUET, (5, 44), choices={"seed": 2}, armatures=ACTORS,
                fitted={"Partner": fit})
    args = Namespace(worker_command=None, path_map=[], scheduler=None, chunk_frames=20, warmup=5, overlap=3)
    batch = cmd_batch.Batch(args, [take], [], tmp_path / "chunks")
    run = cmd_batch.TakeRun(take, plan_chunks(5, 44, 20, 5, 3), [], [])
    argv = batch.chunk_argv(run, run.plan[1])
    words = argv[argv.index("track-chunk"):]
    assert [words[i + 1] for i, a in enumerate(words) if a == "--armature"] == list(ACTORS)
    assert words[words.index("--actor") + 1] == f"Partner={fit.resolve()}"
    assert (words[words.index("--seed") + 1], words[words.index("--frames") + 1]) == ("2", "20-44")
    parsed = build_parser().parse_args(words)
    _settings, actors, key = cmd_track_chunk.take_inputs(parsed)
    assert actors.names == list(ACTORS) and actors.folders == list(ACTORS)
    assert actors.calibrations[0] is None and actors.calibrations[1]["overall"] == 1.02
    assert key == cmd_batch.take_key(take)
