"""A take tracked in chunks by `batch` against the same take in one piece, the result folder it writes, a rerun
that tracks nothing again, and a Dask cluster (a scheduler and two `dask worker` processes on 127.0.0.1) that
loses a worker to SIGKILL mid-chunk and still gives the same take.

The preview preset (50 particles x 4 iterations; at 10 x 2 without the local fit both runs drift 100 mm and more
from the truth by frame 11, so their distance measures nothing) on the walk's frames 0-11 in chunks of 6 with a
warm-up of 3 and an overlap of 2: two chunks, tracked 0-7 and 3-11."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from scene_helpers import cli_environment, scene_dir

WALK = scene_dir("walk")
FAST = ["--preset", "preview", "--backend", "fast"]
PLAN = ["--chunk-frames", "6", "--warmup", "3", "--overlap", "2"]
# The 15 joints' mean distance of the stitched take (as solved) to the take in one piece, frames 0-11: measured
# 2.6 mm, at most 8.0 on a frame (docs/batch.md, "Measured"); the bounds leave room for other machines' floats.
ONE_PIECE_BOUND_MM = 10.0
ONE_PIECE_FRAME_BOUND_MM = 25.0

pytestmark = pytest.mark.slow


def _takes(tmp_path):
    path = tmp_path / "takes.toml"
    path.write_text(f'[[take]]\nname = "walk"\nscene = "{WALK / "subject.blend"}"\ncapture = "{WALK}"\n'
                    'frames = "0-11"\n')
    return path


def _batch(takes, out, *where, env=None, timeout=900):
    cmd = [sys.executable, "-m", "markerless_mocap", "batch", str(takes), "--out", str(out), *where, *PLAN, *FAST,
           "--no-overlays"]
    return subprocess.run(cmd, capture_output=True, text=True, env=env or cli_environment(), timeout=timeout)


@pytest.fixture(scope="module")
def local_batch(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("batch")
    takes = _takes(tmp)
    t0 = time.perf_counter()
    done = _batch(takes, tmp / "out", "--workers", "1")
    assert done.returncode == 0, done.stderr[-3000:]
    return tmp, takes, time.perf_counter() - t0


def _poses(folder, name="poses.npz"):
    with np.load(folder / name) as data:
        return data["frames"], data["poses"]


def test_the_batch_writes_the_take_and_a_rerun_tracks_nothing_again(local_batch):
    tmp, takes, seconds = local_batch
    out = tmp / "out" / "walk"
    for name in ("joints.npz", "poses.npz", "joints_raw.npz", "poses_raw.npz", "keypoints.npz", "report.json",
                 "animation.bvh", "animation.fbx", "tracked.blend"):
        assert (out / name).is_file(), name
    frames, _ = _poses(out)
    assert list(frames) == list(range(12))
    report = json.loads((out / "report.json").read_text())
    batch = report["batch"]
    assert [c["track"] for c in batch["chunks"]] == [[0, 7], [3, 11]]
    (overlap,) = batch["overlaps"]
    assert overlap["frames"] == [6, 7] and overlap["mean_joint_mm"] >= 0
    assert report["smoothing"]["cutoff_hz"] == 8.0
    progress = json.loads((tmp / "out" / "batch-progress.json").read_text())
    assert progress["state"] == "done" and progress["takes"][0]["state"] == "done"
    assert progress["total"]["chunks_done"] == progress["total"]["chunks_total"] == 2
    chunk_files = sorted((tmp / "out" / "_chunks" / "walk").glob("*/chunk.json"))
    before = [p.read_text() for p in chunk_files]
    stitched = (out / "report.json").stat().st_mtime_ns
    t0 = time.perf_counter()
    again = _batch(takes, tmp / "out", "--workers", "1")
    assert again.returncode == 0, again.stderr[-3000:]
    assert [p.read_text() for p in chunk_files] == before  # the finished chunks were not tracked again
    assert time.perf_counter() - t0 < seconds
    # nor stitched again: the same chunks and settings as the result already there
    assert "already stitched" in again.stderr and (out / "report.json").stat().st_mtime_ns == stitched


def test_a_rerun_with_other_stitch_settings_stitches_again(local_batch, tmp_path):
    tmp, takes, _ = local_batch
    shutil.copytree(tmp / "out", tmp_path / "out")
    again = _batch(takes, tmp_path / "out", "--workers", "1", "--smooth", "5")
    assert again.returncode == 0, again.stderr[-3000:]
    assert "already stitched" not in again.stderr
    report = json.loads((tmp_path / "out" / "walk" / "report.json").read_text())
    assert report["smoothing"]["cutoff_hz"] == 5.0


def test_chunks_stitched_equal_the_take_in_one_piece_within_the_bound(local_batch, tmp_path):
    tmp, _, _ = local_batch
    from markerless_mocap.core.results.evaluation import joint_indices
    from markerless_mocap.core.results.result_folder import load_joints

    whole = subprocess.run([sys.executable, "-m", "markerless_mocap", "track-chunk", "--scene",
                            str(WALK / "subject.blend"), "--capture", str(WALK), "--take", "walk", "--frames", "0-11",
                            "--chunks", str(tmp_path), *FAST], capture_output=True, text=True, env=cli_environment())
    assert whole.returncode == 0, whole.stderr[-3000:]
    folder = tmp_path / "walk" / next(p.name for p in (tmp_path / "walk").iterdir() if not p.name.startswith("."))
    names, frames, one_piece = load_joints(folder / "joints.npz")
    _, stitched_frames, stitched = load_joints(tmp / "out" / "walk" / "joints_raw.npz")
    assert list(frames) == list(stitched_frames) == list(range(12))
    idx = joint_indices(names, "walk")
    gap = np.linalg.norm(stitched[:, idx] - one_piece[:, idx], axis=-1).mean(axis=1) * 1e3
    print("stitched vs one piece, per frame (mm):", np.round(gap, 1))
    assert np.all(gap[:6] < 1e-6)  # chunk 0 starts where the one-piece run does: the same frames
    assert gap.mean() < ONE_PIECE_BOUND_MM and gap.max() < ONE_PIECE_FRAME_BOUND_MM
    # and so its per-frame report there: what the tracker set aside or left out, frame by frame
    from markerless_mocap.core.batch.stitch_report import FRAME_MAPS
    whole_report = json.loads((folder / "report.json").read_text())
    stitched_report = json.loads((tmp / "out" / "walk" / "report.json").read_text())
    for key in FRAME_MAPS:
        first_chunk = {f: v for f, v in (whole_report.get(key) or {}).items() if int(f) < 6}
        assert {f: v for f, v in (stitched_report.get(key) or {}).items() if int(f) < 6} == first_chunk, key


def _start(cmd, log):
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=cli_environment(), start_new_session=True)


def _stop(proc):
    """End a process this test started and every process of its session (the chunk commands it started, which
    outlive a worker killed alone)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait(timeout=30)


def test_a_cluster_losing_a_worker_mid_chunk_gives_the_same_take(local_batch, tmp_path):
    import psutil

    tmp, takes, _ = local_batch
    bin_dir = os.path.dirname(sys.executable)
    scheduler_file = tmp_path / "scheduler.json"
    log = open(tmp_path / "cluster.log", "w")
    procs = []
    try:
        procs.append(_start([os.path.join(bin_dir, "dask"), "scheduler", "--scheduler-file", str(scheduler_file),
                             "--host", "127.0.0.1", "--port", "0", "--no-dashboard"], log))
        deadline = time.time() + 60
        while not scheduler_file.exists() and time.time() < deadline:
            time.sleep(0.2)
        assert scheduler_file.exists(), "the scheduler did not start"
        workers = [_start([os.path.join(bin_dir, "dask"), "worker", "--scheduler-file", str(scheduler_file),
                           "--nthreads", "1", "--no-nanny", "--host", "127.0.0.1", "--no-dashboard"], log)
                   for _ in range(2)]
        procs += workers
        out = tmp_path / "out"
        batch = _start([sys.executable, "-m", "markerless_mocap", "batch", str(takes), "--out", str(out),
                        "--scheduler", str(scheduler_file), *PLAN, *FAST, "--no-overlays"], log)
        procs.append(batch)
        killed = None
        deadline = time.time() + 600
        while killed is None and time.time() < deadline and batch.poll() is None:
            # mid-chunk: a chunk has solved a frame in its partial folder; kill the worker that runs it
            for report in (out / "_chunks" / "walk").glob(".*.partial-*/report.json") if (out / "_chunks").exists() \
                    else []:
                pid = int(report.parent.name.rsplit("-", 1)[1])
                try:
                    parent = psutil.Process(pid).ppid()
                except psutil.NoSuchProcess:
                    continue
                victim = next((w for w in workers if w.pid == parent), None)
                if victim is not None:
                    victim.send_signal(signal.SIGKILL)
                    killed = victim
                    break
            time.sleep(0.2)
        assert killed is not None, "no chunk was seen running on a worker"
        assert batch.wait(timeout=600) == 0, (tmp_path / "cluster.log").read_text()[-3000:]
        frames, poses = _poses(out / "walk")
        undisturbed_frames, undisturbed = _poses(tmp / "out" / "walk")
        assert list(frames) == list(undisturbed_frames)
        assert np.array_equal(poses, undisturbed)
    finally:
        for proc in reversed(procs):
            _stop(proc)
        log.close()
