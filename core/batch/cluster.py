"""Chunk commands run on Dask: a LocalCluster on this machine or the workers of a scheduler elsewhere.

Each task is the standard library's `subprocess.run` of a chunk's command line
(docs/batch.md, "Why a subprocess per chunk"): the scheduler unpickles only a call it already knows (never this
package), the worker's own thread stays free to answer the scheduler's heartbeats however long the chunk tracks,
and the chunk's process holds the numba functions, the landmark network and the footage. A chunk's exit code comes
back as the task's result, for the batch to tell the user's error from a crash (operators/cmd_batch.py); a command
submitted with `check` raises instead and Dask runs it again up to `retries` times. A worker that dies is Dask's to
notice, and its task runs on another worker.
"""
from __future__ import annotations

import os
import subprocess
import uuid
from pathlib import Path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def default_workers():
    """One chunk per two cores: one tracker keeps two cores busy (its search and the next frame's observation)."""
    return max(1, (os.cpu_count() or 2) // 2)


def chunk_environment(threads, base=None):
    """The environment of a chunk's process on this machine: the thread pools capped at `threads`."""
    env = dict(os.environ if base is None else base)
    for name in THREAD_VARIABLES:
        env[name] = str(int(threads))
    return env


def failure_text(exc):
    """What a failed task says: the chunk command's own last message, else the exception."""
    stderr = getattr(exc, "stderr", None)
    if stderr:
        lines = [line.strip() for line in str(stderr).splitlines() if line.strip()]
        mine = [line for line in lines if line.startswith("markerless_mocap")]
        if mine or lines:
            return (mine or lines)[-1]
    code = getattr(exc, "returncode", None)
    if code is not None:
        return f"the chunk command ended with exit code {code}"
    return f"{type(exc).__name__}: {exc}"


class ChunkRunner:
    """Submits chunk commands to Dask and reports their futures' states. `scheduler`: an address
    (tcp://host:8786) or a scheduler file; None starts a LocalCluster of `workers` single-threaded workers in this
    process (threads: each task only waits for its subprocess)."""

    def __init__(self, workers=None, scheduler=None, retries=2, env=None):
        self.workers = workers or default_workers()
        self.scheduler = scheduler
        self.retries = int(retries)
        self.env = env
        self.cluster = self.client = None

    def __enter__(self):
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=False,
                                        dashboard_address=None)
            self.client = Client(self.cluster)
        elif Path(str(self.scheduler)).is_file():
            self.client = Client(scheduler_file=str(self.scheduler))
        else:
            self.client = Client(str(self.scheduler))
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.client = self.cluster = None

    def submit(self, name, argv, check=True):
        """Run `argv` on a worker; returns the future (its result the CompletedProcess). With `check` a non-zero
        exit raises and Dask runs the command again up to `retries` times; without, the caller reads the exit code
        and decides (a user's error is not run again)."""
        return self.client.submit(subprocess.run, list(map(str, argv)), check=check, capture_output=True, text=True,
                                  env=self.env, key=f"{name}-{uuid.uuid4().hex[:8]}", pure=False,
                                  retries=self.retries if check else 0)


__all__ = ["ChunkRunner", "THREAD_VARIABLES", "chunk_environment", "default_workers", "failure_text"]
