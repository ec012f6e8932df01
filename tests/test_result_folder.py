"""The result folder under stress: a folder that cannot be written, a disk that fills up during a run
(ENOSPC, simulated), and atomic files (a write that fails leaves the earlier version, no debris)."""
import errno
import os
from dataclasses import dataclass, field

import numpy as np
import pytest

from markerless_mocap.core import atomic_files
from markerless_mocap.core.results.result_folder import ResultWriteError, ResultWriter
from markerless_mocap.core.tracking.settings import FrameEstimate, TrackingSettings


@dataclass
class _Skeleton:
    bone_names: list = field(default_factory=lambda: ["hips", "spine", "head"])


@dataclass
class _Body:
    skeleton: _Skeleton = field(default_factory=_Skeleton)
    n_dof: int = 4
    dof_names: list = field(default_factory=lambda: ["a", "b", "c", "d"])


def _estimate(frame):
    return FrameEstimate(frame=frame, pose=np.full(4, float(frame)), joints=np.full((3, 3), float(frame)),
                         energy=1.0 / (frame + 1), seconds=0.1, evaluations=10)


def _writer(out):
    return ResultWriter(out, _Body(), TrackingSettings(), info={"cameras": ["a", "b"]})


def _no_partial_files(folder):
    return [p.name for p in folder.iterdir() if ".partial" in p.name or p.name.startswith(".write_probe")]


def test_every_result_file_is_renamed_into_place(tmp_path, monkeypatch):
    renamed = []
    real_replace = os.replace
    monkeypatch.setattr(atomic_files.os, "replace",
                        lambda a, b: (renamed.append(os.path.basename(b)), real_replace(a, b)))
    writer = _writer(tmp_path / "out")
    writer.add(_estimate(0), tracker_state={"rng": 1})
    on_disk = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert on_disk == ["checkpoint.npz", "joints.npz", "poses.npz", "report.json"]
    assert sorted(renamed) == on_disk  # each one written under another name and renamed: none in place


def test_a_write_that_fails_halfway_leaves_the_earlier_file(tmp_path):
    target = tmp_path / "poses.npz"
    target.write_bytes(b"the earlier version")

    def half_then_fail(path):
        with atomic_files.atomic_path(path) as tmp:
            tmp.write_bytes(b"half of a new")
            raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError):
        half_then_fail(target)
    assert target.read_bytes() == b"the earlier version" and _no_partial_files(tmp_path) == []


def test_two_processes_writing_one_file_at_once_each_rename_a_whole_one(tmp_path):
    """Two runs that fill the same cache at once (two tracks started together on a new machine, a batch's
    workers) each write under a name of their own: neither fails, and the file is one of theirs, whole."""
    import subprocess
    import sys

    target = tmp_path / "motion.npz"
    writer = ("import sys\nfrom markerless_mocap.core.atomic_files import atomic_path\n"
              "for _ in range(200):\n"
              "    with atomic_path(sys.argv[1]) as tmp:\n"
              "        tmp.write_bytes(sys.argv[2].encode() * 20000)\n")
    runs = [subprocess.Popen([sys.executable, "-c", writer, str(target), tag]) for tag in "ab"]
    assert [run.wait(timeout=120) for run in runs] == [0, 0]
    assert target.read_bytes() in (b"a" * 20000, b"b" * 20000) and _no_partial_files(tmp_path) == []


def test_disk_full_during_a_run_keeps_the_solved_frames(tmp_path, monkeypatch):
    out = tmp_path / "out"
    writer = _writer(out)
    for f in range(3):
        writer.add(_estimate(f), tracker_state={"after": f})
    real_savez = np.savez

    def savez_filling_the_disk(fh, **arrays):
        real_savez(fh, **arrays)  # bytes reach the temporary file, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez", savez_filling_the_disk)
    with pytest.raises(ResultWriteError) as err:
        writer.add(_estimate(3), tracker_state={"after": 3})
    assert str(err.value) == (f"could not write frame 3 to {out}: the disk is full; frames 0-2 (3) are saved there; "
                              "free space and continue with --resume")
    assert err.value.errno == errno.ENOSPC
    monkeypatch.setattr(np, "savez", real_savez)
    assert list(np.load(out / "poses.npz")["frames"]) == [0, 1, 2] and _no_partial_files(out) == []
    assert [e.frame for e in writer.estimates] == [0, 1, 2]
    done, state = _writer(out).load_checkpoint()  # what --resume starts from
    assert [e.frame for e in done] == [0, 1, 2] and state == {"after": 2}


def test_a_result_folder_that_cannot_be_created_is_named(tmp_path):
    (tmp_path / "a_file").write_text("not a folder")
    with pytest.raises(ResultWriteError) as err:
        _writer(tmp_path / "a_file" / "result")
    assert str(err.value).startswith(f"the result folder {tmp_path / 'a_file' / 'result'} cannot be written (")
    assert str(err.value).endswith("choose another result folder, or fix its permissions")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_result_folder_is_named(tmp_path):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        with pytest.raises(ResultWriteError, match="cannot be written \\(Permission denied\\)"):
            _writer(out)
    finally:
        out.chmod(0o700)


@pytest.mark.slow
def test_track_stops_in_one_line_when_the_disk_fills(tmp_path, monkeypatch, capsys):
    pytest.importorskip("bpy")
    from scene_helpers import scene_dir

    from markerless_mocap.core.results import result_folder as results
    from markerless_mocap.operators.cli import main

    real_write = results.ResultWriter.write

    def write_until_full(self):
        if len(self.estimates) > 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_write(self)

    monkeypatch.setattr(results.ResultWriter, "write", write_until_full)
    out = tmp_path / "out"
    code = main(["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(scene_dir("walk")),
                 "--out", str(out), "--frames", "0-4", "--particles", "10", "--iterations", "2",
                 "--likelihood", "silh+edge", "--no-export", "--no-overlays"])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1
    assert last == (f"markerless_mocap track: could not write frame 2 to {out}: the disk is full; frames 0-1 (2) "
                    "are saved there; free space and continue with --resume")
    assert list(np.load(out / "poses.npz")["frames"]) == [0, 1]
