"""Peak memory of a long take: does a headless `track` run stay flat in memory as the take grows?

Builds a long capture in a temporary folder by playing a sample scene's videos forwards and backwards
(walk: 60 frames -> 0..59, 58..1, 0..59, ... up to --frames), tracks it with a small budget in a real
`python -m markerless_mocap track` process, and reads that process's peak resident memory (VmHWM,
Linux /proc) when frame 100 is saved, and its exact peak (rusage) when the run ends. Nothing is written
to the repository.

    .venv/bin/python tools/memory_bench.py [--scene walk] [--frames 1000] [--particles 10] [--iterations 2]
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]


def ping_pong_index(i, n):
    """Frame of an n-frame clip shown at step i when it plays forwards, then backwards, and so on."""
    period = 2 * (n - 1)
    k = i % period
    return k if k < n else period - k


def build_long_capture(scene, dest, n_frames):
    """A copy of the scene's capture whose videos are n_frames long, played forwards and backwards."""
    dest.mkdir(parents=True)
    shutil.copy(scene / "calibration.toml", dest / "calibration.toml")
    if (scene / "background").is_dir():
        shutil.copytree(scene / "background", dest / "background")
    (dest / "videos").mkdir()
    for video in sorted((scene / "videos").glob("*.mp4")):
        cap = cv2.VideoCapture(str(video))
        fps = cap.get(cv2.CAP_PROP_FPS)
        clip = []
        while True:
            ok, img = cap.read()
            if not ok:
                break
            clip.append(img)
        cap.release()
        h, w = clip[0].shape[:2]
        writer = cv2.VideoWriter(str(dest / "videos" / video.name), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        for i in range(n_frames):
            writer.write(clip[ping_pong_index(i, len(clip))])
        writer.release()
    return dest


def peak_rss_mb(pid):
    """The running process's peak resident set so far (VmHWM), in MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc: this bench needs Linux")


def saved_frames(out):
    try:
        with np.load(out / "poses.npz") as data:
            return len(data["frames"])
    except (OSError, ValueError, KeyError):
        return 0


def package_path():
    """A folder holding a `markerless_mocap` link to this checkout, whatever the checkout is called."""
    holder = Path(tempfile.mkdtemp(prefix="mocap_pkg_"))
    (holder / "markerless_mocap").symlink_to(REPO, target_is_directory=True)
    return holder


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="walk", help="sample scene under sample_scenes/ (default: walk)")
    p.add_argument("--frames", type=int, default=1000)
    p.add_argument("--checkpoint", type=int, default=100, help="also report the peak after this many frames")
    p.add_argument("--particles", type=int, default=10)
    p.add_argument("--iterations", type=int, default=2)
    p.add_argument("--likelihood", default=None, help="default: the product's default")
    args = p.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="mocap_memory_bench_") as tmp:
        tmp = Path(tmp)
        scene = REPO / "sample_scenes" / args.scene
        capture = build_long_capture(scene, tmp / "capture", args.frames)
        out = tmp / "result"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(package_path()), os.environ.get("PYTHONPATH", "")]))
        command = [sys.executable, "-m", "markerless_mocap", "track", "--scene", str(scene / "subject.blend"),
                   "--capture", str(capture), "--out", str(out), "--frames", f"0-{args.frames - 1}",
                   "--particles", str(args.particles), "--iterations", str(args.iterations),
                   "--no-export", "--no-overlays"]
        if args.likelihood:
            command += ["--likelihood", args.likelihood]
        started = time.monotonic()
        # a file, not a pipe: 1000 progress lines would fill a pipe and stall the run
        log = open(tmp / "track.log", "w+")
        run = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=log)
        at_checkpoint = None
        while True:
            pid, status, usage = os.wait4(run.pid, os.WNOHANG)  # reaps the run itself: its rusage is exact
            if pid:
                peak, code = usage.ru_maxrss / 1024, os.waitstatus_to_exitcode(status)
                break
            done = saved_frames(out)
            if at_checkpoint is None and done >= args.checkpoint:
                at_checkpoint = (done, peak_rss_mb(run.pid))
                print(f"peak RSS after {done} frames: {at_checkpoint[1]:.0f} MB "
                      f"({time.monotonic() - started:.0f} s)", flush=True)
            time.sleep(0.2)
        if code != 0:
            log.seek(0)
            sys.exit(f"track failed ({code}): {log.read()[-2000:]}")
        done = saved_frames(out)
        print(f"peak RSS after {done} frames: {peak:.0f} MB ({time.monotonic() - started:.0f} s)")
        if at_checkpoint:
            print(f"growth from frame {at_checkpoint[0]} to {done}: {100 * (peak / at_checkpoint[1] - 1):+.1f} %")
        log.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
