"""A real headless run killed with SIGKILL after a frame is saved, then `--resume`: the poses equal an
uninterrupted run's with the same seed, and the kill left no half-written file. Two subprocesses run
side by side (the uninterrupted reference and the one that is killed), then the resume; about a minute."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from scene_helpers import cli_environment, scene_dir

from markerless_mocap.core.tracking import checkpoint

pytest.importorskip("bpy")
if os.name != "posix":
    pytest.skip("SIGKILL is POSIX", allow_module_level=True)

FRAMES = "0-5"
KILL_AFTER = 2  # frames saved when the kill comes (frames 0 and 1)


def _track_command(out, *extra):
    return [sys.executable, "-m", "markerless_mocap", "track", "--scene", str(scene_dir("walk") / "subject.blend"),
            "--capture", str(scene_dir("walk")), "--out", str(out), "--frames", FRAMES, "--particles", "20",
            "--iterations", "3", "--seed", "5", "--no-export", "--no-overlays", *extra]


def _saved_frames(out):
    try:
        with np.load(out / "poses.npz") as data:
            return list(data["frames"])
    except (OSError, ValueError, KeyError):  # not written yet
        return []


@pytest.mark.slow
def test_sigkill_then_resume_gives_the_uninterrupted_poses(tmp_path):
    env = cli_environment()
    full_out, killed_out = tmp_path / "full", tmp_path / "killed"
    full = subprocess.Popen(_track_command(full_out), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    victim = subprocess.Popen(_track_command(killed_out), env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while len(_saved_frames(killed_out)) < KILL_AFTER:
            assert victim.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no frame saved in time"
            time.sleep(0.05)
        victim.send_signal(signal.SIGKILL)
        assert victim.wait(30) == -signal.SIGKILL
    finally:
        if victim.poll() is None:
            victim.kill()
    saved = _saved_frames(killed_out)
    assert KILL_AFTER <= len(saved) < 6, saved  # killed part-way
    leftovers = [p.name for p in killed_out.iterdir() if ".partial" in p.name]
    for name in ("poses.npz", "joints.npz", "checkpoint.npz"):  # whatever the kill interrupted, each file loads
        assert (killed_out / name).exists()
    with np.load(killed_out / "joints.npz") as joints:
        assert len(joints["frames"]) in (len(saved), len(saved) - 1, len(saved) + 1)
    estimates, _, _ = checkpoint.read(killed_out / "checkpoint.npz")  # written after poses.npz: a frame behind at most
    assert [e.frame for e in estimates] in (saved, saved[:-1])

    resumed = subprocess.run(_track_command(killed_out, "--resume"), env=env, capture_output=True, text=True,
                             timeout=240)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert "resuming after frame" in resumed.stderr
    assert full.wait(240) == 0, full.stderr.read()[-2000:]
    with np.load(full_out / "poses.npz") as a, np.load(killed_out / "poses.npz") as b:
        assert list(b["frames"]) == [0, 1, 2, 3, 4, 5]
        np.testing.assert_array_equal(a["poses"], b["poses"])
    print(f"killed after {len(saved)} saved frames; partial files left by the kill: {leftovers}")
