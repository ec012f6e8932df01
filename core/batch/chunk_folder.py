"""Where a chunk's result lives, and how it appears there: whole or not at all.

    CHUNKS/<take>/<first:06d>-<last:06d>_<key>/   joints.npz poses.npz keypoints.npz report.json checkpoint.npz
                                                  chunk.json (what was tracked, with what, where, when)
                                                  (a take of several actors: report.json and chunk.json, and
                                                  actors/<armature>/ with each actor's files, as `track` writes them)

`<key>` is 12 hex digits of a SHA-256 over what decides the chunk's poses: the tracking settings (the backend left
out: each scores the same energy), the subject file's bytes, the armature's name, the actor calibration and the
capture folder's name. A chunk is tracked into a hidden sibling named after the host and process, then renamed into
place in one step (the same file system): a folder under the final name is a finished chunk, so a rerun or a retried
task never tracks it again, and two workers racing on one chunk (a worker thought dead that was not) leave one
result. The stitch reads the estimates back from checkpoint.npz (core/tracking/checkpoint.py).
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import socket
import time
from pathlib import Path

from ..errors import InputError
from ..results.result_folder import actor_result_folder
from ..tracking import checkpoint
from .plan import frame_range_name

FORMAT = 1  # of chunk.json and of the key: a change of either starts the chunks afresh
INFO_FILE = "chunk.json"
REPORT_FILE = "report.json"  # the chunk's own report, as `track` writes it
TAKE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
CHUNKS_FOLDER = "_chunks"  # batch's default place for the chunk folders, inside its --out


class ChunkError(InputError):
    """A chunk folder that is missing or cannot be read; the message names it and the fix."""


def check_take_name(name):
    """The take's name as a folder name, or an InputError saying what it may hold."""
    if not isinstance(name, str) or not TAKE_NAME.match(name) or name == CHUNKS_FOLDER:
        raise InputError(f"take name {name!r}: use letters, digits, '-', '_' and '.', starting with a letter or a "
                         f"digit (it names the take's result folder), and not {CHUNKS_FOLDER!r}")
    return name


def file_digest(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def chunk_key(settings, subject_file, armature=None, actor=None, capture=None):
    """The 12-hex key of a chunk's inputs. `settings`: TrackingSettings.to_dict(); `subject_file`: the .blend;
    `actor`: the actor calibration's dict or None; `capture`: the capture folder (only its name counts: the same
    capture is mounted under other paths on other machines)."""
    plain = {k: v for k, v in settings.items() if k != "backend"}
    blob = json.dumps({"format": FORMAT, "settings": plain, "subject": file_digest(subject_file),
                       "armature": armature, "actor": actor,
                       "capture": None if capture is None else Path(capture).resolve().name},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


class ChunkFolder:
    """The folder of one chunk: CHUNKS/<take>/<first>-<last>_<key>."""

    def __init__(self, chunks_root, take, track, key):
        self.take = check_take_name(take)
        self.track = (int(track[0]), int(track[1]))
        self.key = key
        self.path = Path(chunks_root) / take / f"{frame_range_name(*self.track)}_{key}"

    @property
    def done(self):
        return (self.path / INFO_FILE).is_file()

    def new_partial(self):
        """A fresh hidden sibling to track into (one per host and process, so attempts never share one)."""
        host = re.sub(r"[^A-Za-z0-9.-]", "_", socket.gethostname()) or "host"
        partial = self.path.with_name(f".{self.path.name}.partial-{host}-{os.getpid()}")
        if partial.exists():
            shutil.rmtree(partial)
        partial.mkdir(parents=True)
        return partial

    def publish(self, partial, info):
        """Write chunk.json into `partial` and rename it to the chunk's folder. If another attempt finished first,
        its folder stays and `partial` is removed. Returns the chunk's folder."""
        info = {"format": FORMAT, "take": self.take, "track": list(self.track), "key": self.key,
                "host": socket.gethostname(), "pid": os.getpid(), "finished": time.time(), **info}
        tmp = Path(partial) / f".{INFO_FILE}.partial"
        tmp.write_text(json.dumps(info, indent=1))
        os.replace(tmp, Path(partial) / INFO_FILE)
        try:
            os.rename(partial, self.path)
        except OSError:
            if not self.done:
                raise
            shutil.rmtree(partial, ignore_errors=True)
        return self.path

    def info(self):
        try:
            return json.loads((self.path / INFO_FILE).read_text())
        except (OSError, ValueError) as exc:
            raise ChunkError(f"chunk {self.path}: {INFO_FILE} cannot be read ({exc}); delete the folder and run "
                             "the chunk again") from None

    def report(self, actor=None):
        """The chunk's (or its `actor`'s) report.json as a dict ({} when it has none: chunks tracked before it was
        kept)."""
        try:
            return json.loads((actor_result_folder(self.path, actor) / REPORT_FILE).read_text())
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            raise ChunkError(f"chunk {self.path}: {REPORT_FILE} cannot be read ({exc}); delete the folder and run "
                             "the chunk again") from None

    def estimates(self, actor=None):
        """{frame: FrameEstimate} of the finished chunk (of its `actor`, by folder name, in a take of several)."""
        if not self.done:
            raise ChunkError(f"chunk {self.path} is not finished: run its track-chunk command (or the batch) first")
        path = actor_result_folder(self.path, actor) / checkpoint.FILE_NAME
        if not path.is_file():
            raise ChunkError(f"chunk {self.path} holds no {path.relative_to(self.path)}: it was tracked for other "
                             "actors; delete the folder and run the chunk again")
        estimates, _state, _settings = checkpoint.read(path)
        return {int(e.frame): e for e in estimates}


__all__ = ["CHUNKS_FOLDER", "ChunkError", "ChunkFolder", "INFO_FILE", "check_take_name", "chunk_key",
           "file_digest"]
