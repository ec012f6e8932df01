"""The batch's progress file: what a caller that did not start the batch's process in its own terminal (the
Blender panel) polls. One JSON file, replaced in one step, so a reader never sees half of it.

    {"state": "planning" | "running" | "stitching" | "done" | "failed" | "cancelled", "started", "updated",
     "error": null | text, "total": {"chunks_done", "chunks_total", "frames_done", "frames_total", "seconds_left"},
     "takes": [{"name", "state", "chunks_done", "chunks_total", "frames", "result", "error"}]}

A take's state: queued, running, stitching, done or failed (its error names the reason). "done" for the batch
means it ended; each take says how.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from ..atomic_files import write_json

FILE_NAME = "batch-progress.json"
CANCEL_FILE = "batch-cancel"  # its presence asks a running batch to stop


def frames_solved(result_folder):
    """Frames a result folder being tracked has solved so far (its report.json, rewritten as frames are solved; for
    several actors, the frames every actor has solved); 0 while it has none, or cannot be read."""
    try:
        report = json.loads((Path(result_folder) / "report.json").read_text())
        if "actors" in report:
            return min((frames_solved(Path(result_folder) / a["folder"]) for a in report["actors"]), default=0)
        return int(report["totals"]["frames"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


def write_progress(folder, progress):
    progress = {**progress, "updated": time.time()}
    write_json(Path(folder) / FILE_NAME, progress)


def read_progress(folder):
    """The batch's last progress, or None before it wrote one (or while the file cannot be read)."""
    try:
        return json.loads((Path(folder) / FILE_NAME).read_text())
    except (OSError, ValueError):
        return None


def request_cancel(folder):
    Path(folder).mkdir(parents=True, exist_ok=True)
    (Path(folder) / CANCEL_FILE).write_text("cancel\n")


def cancel_requested(folder):
    return (Path(folder) / CANCEL_FILE).exists()


def bar(done, total, width=24):
    """A text bar: [#########---------------]."""
    filled = 0 if total <= 0 else int(round(width * min(done, total) / total))
    return "[" + "#" * filled + "-" * (width - filled) + "]"


def format_duration(seconds):
    if seconds is None:
        return "?"
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def progress_lines(progress):
    """The progress as lines of text: one per take, then the total with the time left."""
    lines = []
    width = max([len(t["name"]) for t in progress["takes"]] + [5])
    for t in progress["takes"]:
        state = t["state"] if t["state"] != "failed" else f"failed: {t['error']}"
        lines.append(f"{t['name']:<{width}} {bar(t['chunks_done'], t['chunks_total'])} "
                     f"{t['chunks_done']}/{t['chunks_total']} chunks  {state}")
    total = progress["total"]
    lines.append(f"{'total':<{width}} {bar(total['frames_done'], total['frames_total'])} "
                 f"{total['chunks_done']}/{total['chunks_total']} chunks, {total['frames_done']}/"
                 f"{total['frames_total']} frames, {format_duration(total['seconds_left'])} left")
    return lines


__all__ = ["CANCEL_FILE", "FILE_NAME", "bar", "cancel_requested", "format_duration", "progress_lines",
           "read_progress", "request_cancel", "write_progress"]
