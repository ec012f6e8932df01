"""Esc in Blender during a real tracking run (the modal operator with its worker thread, a real
TrackSession on the walk scene): the frames solved before Esc keep their keys on the armature, and
the result folder holds exactly those frames (joints, poses, report, BVH). The same when Blender
itself ends the operator (cancel)."""
import importlib
import json
import time
import types

import numpy as np
import pytest

from scene_helpers import scene_dir

pytestmark = pytest.mark.bpy


def _operator(track_module, reports):
    """The modal operator's methods on a stand-in instance (bpy does not build operators outside a call)."""
    op = types.SimpleNamespace(report=lambda level, message: reports.append((set(level), message)))
    for name in ("_begin", "_show", "_end", "_refresh", "_cleanup", "modal", "cancel"):
        setattr(op, name, types.MethodType(getattr(track_module.MOCAP_OT_track, name), op))
    return op


def _context(bpy):
    return types.SimpleNamespace(scene=bpy.context.scene, preferences=bpy.context.preferences, workspace=None,
                                 screen=None, window=object(),
                                 window_manager=types.SimpleNamespace(event_timer_remove=lambda timer: None))


def _start(addon_module_name, bpy, out, frames=(0, 5)):
    track = importlib.import_module(f"{addon_module_name}.operators.track")
    bpy.ops.wm.open_mainfile(filepath=str(scene_dir("walk") / "subject.blend"))
    m = bpy.context.scene.mocap
    m.capture_dir, m.output_dir = str(scene_dir("walk")), str(out)
    m.particles, m.iterations, m.seed, m.likelihood = 10, 2, 0, "silh+edge"
    m.use_frame_range, m.frame_start, m.frame_end = True, *frames
    reports = []
    op, context = _operator(track, reports), _context(bpy)
    job, session = op._begin(context)
    assert job is not None, reports
    op._job, op._timer = job, object()
    job.start(session)
    return op, context, job, reports


def _timer(op, context):
    return op.modal(context, types.SimpleNamespace(type="TIMER", value="NOTHING"))


def _wait_for_keys(op, context, job, n, timeout=120):
    deadline = time.monotonic() + timeout
    while len(job.estimates) < n:
        assert time.monotonic() < deadline and not job.error, job.error
        assert _timer(op, context) == {"RUNNING_MODAL"}
        time.sleep(0.05)


def _keyed_frames(addon_module_name, arm):
    compat = importlib.import_module(f"{addon_module_name}.addon.anim_compat")  # knows layered actions
    return [int(round(f)) for f in compat.keyed_frames(arm)]


@pytest.mark.slow
def test_esc_keeps_the_keys_and_writes_the_results_of_the_solved_frames(addon_module_name, bpy_module, tmp_path):
    bpy = bpy_module
    out = tmp_path / "result"
    op, context, job, reports = _start(addon_module_name, bpy, out)
    _wait_for_keys(op, context, job, 2)
    assert op.modal(context, types.SimpleNamespace(type="ESC", value="PRESS")) == {"RUNNING_MODAL"}
    deadline = time.monotonic() + 120
    while (result := _timer(op, context)) == {"RUNNING_MODAL"}:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert result == {"CANCELLED"}
    solved = [e.frame for e in job.estimates]
    assert 2 <= len(solved) < 6 and solved == list(range(len(solved)))  # stopped part-way, in order
    m = bpy.context.scene.mocap
    assert m.status == f"Cancelled after {len(solved)} frames (keys kept)" and not m.is_tracking
    assert reports[-1] == ({"WARNING"}, f"Tracking cancelled after {len(solved)} frames; their keys are kept")
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    start = bpy.context.scene.frame_start
    assert _keyed_frames(addon_module_name, arm) == [f + start for f in solved]
    assert list(np.load(out / "poses.npz")["frames"]) == solved
    assert list(np.load(out / "joints.npz")["frames"]) == solved
    assert [f["frame"] for f in json.loads((out / "report.json").read_text())["frames"]] == solved
    bvh = (out / "animation.bvh").read_text()
    assert f"Frames: {len(solved)}" in bvh
    assert not [p.name for p in out.iterdir() if ".partial" in p.name]


def test_blender_ending_the_operator_also_writes_the_results(addon_module_name, bpy_module, tmp_path, monkeypatch):
    """Blender calls cancel() (a file is loaded, the window closes): the worker stops and finish() runs
    for the frames keyed so far (a fake session: the real one is exercised above)."""
    from test_addon_ui import FakeSession

    bpy = bpy_module
    track = importlib.import_module(f"{addon_module_name}.operators.track")
    monkeypatch.setattr(track, "TrackSession", FakeSession)
    monkeypatch.setattr(FakeSession, "block_at", 2)  # the worker waits in the third frame
    bpy.ops.wm.open_mainfile(filepath=str(scene_dir("walk") / "subject.blend"))
    m = bpy.context.scene.mocap
    m.capture_dir, m.output_dir = str(tmp_path / "capture"), str(tmp_path / "out")
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 4
    reports = []
    op, context = _operator(track, reports), _context(bpy)
    job, session = op._begin(context)
    op._job, op._timer = job, object()
    job.start(session)
    assert session.blocked.wait(10)
    _timer(op, context)  # frames 0 and 1 arrive and are keyed
    session.release.set()
    op.cancel(context)
    assert session.finished is not None and session.finished["frames"][:2] == [0, 1]
    assert session.finished["frames"] == [e.frame for e in job.estimates]
    assert not m.is_tracking and m.status.startswith("Cancelled after")
