"""Files that appear whole or not at all: written under a temporary name in the same folder, then
renamed over the target in one step (os.replace is atomic on one file system), so a run killed or
stopped by a full disk leaves the earlier version of every file, never half of a new one."""
import contextlib
import json
import os
from pathlib import Path


def partial_path(path):
    """Where a result file is written before it is renamed into place: same folder (so the rename is
    atomic), same extension (so exporters and video writers pick the right format), this process's own (two
    runs filling the same cache at once each rename a whole file of their own)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path to write `path` to; on success it replaces `path` in one rename, so a kill
    or a full disk never leaves a half-written file (the earlier version stays); on failure it is removed."""
    path = Path(path)
    tmp = partial_path(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_json(path, data):
    """`data` as indented JSON at `path`, whole or not at all."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1))
