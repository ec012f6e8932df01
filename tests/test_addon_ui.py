"""The Blender side: registration, the Mocap sidebar panels, Check Rig, and the Track operator's run loop.

The Track operator is driven here by a fake session (same interface as operators/track_session.py)
so that its own duties are checked: keys are made on the main thread for every solved frame, the
settings reach the session, `finish()` always runs, cancel keeps the solved frames, and errors in the
worker are reported instead of swallowed.
"""
import importlib
import json
import sys
import threading
import time
import types
from collections import namedtuple
from pathlib import Path

import numpy as np
import pytest

from rig_helpers import build_armature

pytestmark = pytest.mark.bpy

PANELS = ("MOCAP_PT_capture", "MOCAP_PT_subject", "MOCAP_PT_track", "MOCAP_PT_results")
OPERATOR_MODULES = ("import_capture", "setup_subject", "calibrate", "track", "track_batch", "export")


def _module(addon_module_name, name):
    return importlib.import_module(f"{addon_module_name}.{name}")


def _operator_classes(addon_module_name):
    return [cls for name in OPERATOR_MODULES for cls in _module(addon_module_name, f"operators.{name}").classes]


# ----------------------------------------------------------------------------- registration
def test_addon_registers_panels_operators_properties_and_cli(addon_module_name, bpy_module):
    bpy = bpy_module
    for name in PANELS:
        panel = getattr(bpy.types, name)
        assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == ("VIEW_3D", "UI", "Mocap")
    classes = _operator_classes(addon_module_name)
    assert {c.__name__ for c in classes} >= {"MOCAP_OT_import_capture", "MOCAP_OT_check_subject", "MOCAP_OT_track",
                                             "MOCAP_OT_export_fbx", "MOCAP_OT_export_bvh"}
    for cls in classes:
        assert cls.__name__.startswith("MOCAP_OT_") and cls.bl_idname.startswith("mocap.")
        op = getattr(bpy.ops.mocap, cls.bl_idname.split(".", 1)[1])
        assert op.poll() is True, cls.bl_idname
    props = bpy.context.scene.mocap
    assert (props.algorithm, props.likelihood, props.particles, props.iterations, props.backend) == (
        "isa", "lsilh+edge+kp", 200, 15, "auto")
    prefs = bpy.context.preferences.addons[addon_module_name].preferences
    assert type(prefs).bl_idname == addon_module_name and prefs.default_backend == "auto"
    ops_pkg = _module(addon_module_name, "operators")
    assert ops_pkg._cli_handle is not None


def test_disable_removes_everything_and_enable_restores_it(addon_module_name, bpy_module):
    import addon_utils

    bpy = bpy_module
    addon_utils.disable(addon_module_name)
    try:
        for name in PANELS:
            assert not hasattr(bpy.types, name)
        assert not hasattr(bpy.types.Scene, "mocap")
        with pytest.raises(AttributeError, match="could not be found"):
            bpy.ops.mocap.track.poll()
        addon = bpy.context.preferences.addons.get(addon_module_name)
        assert addon is None or addon.preferences is None
        assert sys.modules[f"{addon_module_name}.operators"]._cli_handle is None
    finally:
        addon_utils.enable(addon_module_name, default_set=True, handle_error=None)
    assert hasattr(bpy.types, "MOCAP_PT_track") and bpy.ops.mocap.track.poll()
    assert _module(addon_module_name, "operators")._cli_handle is not None


@pytest.mark.slow
def test_blender_command_tracks_the_open_file(addon_module_name, bpy_module, tmp_path):
    """`blender --background SUBJECT.blend --command markerless_mocap track ...`: Blender opens the file,
    then calls the function the add-on registered with the arguments after the name. No --scene:
    the subject is the open file."""
    from conftest import SAMPLE_SCENES

    bpy = bpy_module
    walk = SAMPLE_SCENES / "walk"
    bpy.ops.wm.open_mainfile(filepath=str(walk / "subject.blend"))
    cli = _module(addon_module_name, "operators.cli")
    out = tmp_path / "result"
    code = cli.blender_command(["track", "--capture", str(walk), "--out", str(out), "--frames", "0-1",
                                "--particles", "20", "--iterations", "3", "--no-export", "--no-overlays"])
    assert code == 0
    joints = np.load(out / "joints.npz")
    assert list(joints["frames"]) == [0, 1]
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    assert arm.animation_data is not None and arm.animation_data.action is not None  # keyed in the open file


RESULT_FILES = ("joints.npz", "poses.npz", "report.json", "animation.bvh", "animation.fbx", "tracked.blend")


@pytest.mark.slow
def test_blender_command_with_no_active_object_writes_every_result_file(addon_module_name, bpy_module, tmp_path):
    """A real `blender -b FILE --command markerless_mocap track` has no `context.object`: Blender's BVH
    exporter polls on it and refused to run (issue 14). Same state here: nothing selected, nothing active,
    and the context masks `object` (setting the view layer's active object does not bring it back, as in
    `--command`). The command must still write every result file, exports and overlays included."""
    from conftest import SAMPLE_SCENES

    bpy = bpy_module
    walk = SAMPLE_SCENES / "walk"
    bpy.ops.wm.open_mainfile(filepath=str(walk / "subject.blend"))
    view_layer = bpy.context.view_layer
    for o in view_layer.objects:
        o.select_set(False)
    view_layer.objects.active = None
    no_object = dict(object=None, active_object=None, selected_objects=[], selected_editable_objects=[])
    operators = _module(addon_module_name, "operators")
    assert operators._cli_handle is not None and operators.CLI_NAME == "markerless_mocap"
    cli = _module(addon_module_name, "operators.cli")  # the function registered under that name
    out = tmp_path / "result"
    with bpy.context.temp_override(**no_object):
        view_layer.objects.active = next(o for o in view_layer.objects if o.type == "ARMATURE")
        assert bpy.context.object is None and not bpy.ops.export_anim.bvh.poll()  # the state that failed
        view_layer.objects.active = None
        code = cli.blender_command(["track", "--capture", str(walk), "--out", str(out), "--frames", "0-1",
                                    "--particles", "20", "--iterations", "3"])
    assert code == 0
    for name in RESULT_FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    overlays = sorted(p.name for p in (out / "overlay").glob("*.mp4"))
    assert len(overlays) == 4, overlays
    bvh = (out / "animation.bvh").read_text()
    assert "Frames: 2" in bvh
    assert bpy.context.view_layer.objects.active is None  # the user's selection state is given back


# ----------------------------------------------------------------------------- panels
class _FakeLayout:
    """Stands in for UILayout in background mode and checks what the panels ask it to draw. `folded`: layout
    panels that start closed are drawn closed (as a user first sees them), else every one is drawn open."""

    _icons = None

    def __init__(self, log, folded=False):
        self.log, self.folded = log, folded

    def _sub(self, *_args, **_kwargs):
        return _FakeLayout(self.log, self.folded)

    row = column = box = split = _sub

    def _check_icon(self, icon):
        import bpy

        if _FakeLayout._icons is None:
            _FakeLayout._icons = {i.identifier for i in
                                  bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items}
        assert icon in _FakeLayout._icons, f"unknown icon {icon}"

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))

    def operator(self, idname, icon="NONE", **_kwargs):
        import bpy

        module, op = idname.split(".")
        getattr(getattr(bpy.ops, module), op).get_rna_type()  # raises for an unknown operator
        self._check_icon(icon)
        self.log.append(("operator", idname))

    def label(self, text="", icon="NONE"):
        self._check_icon(icon)
        self.log.append(("label", text))

    def panel(self, idname, default_closed=False):
        """A layout panel (Blender 4.1+), drawn open here so the test sees what it holds."""
        import bpy

        params = {p.identifier for p in bpy.types.UILayout.bl_rna.functions["panel"].parameters}
        assert {"idname", "default_closed"} <= params
        self.log.append(("panel", idname, default_closed))
        body = None if self.folded and default_closed else _FakeLayout(self.log, self.folded)
        return _FakeLayout(self.log, self.folded), body

    def progress(self, factor=0.0, type="BAR", text=""):
        assert 0.0 <= factor <= 1.0 and type in {"BAR", "RING"}
        self.log.append(("progress", factor, text))


def _draw_all(bpy, folded=False, panels=PANELS):
    log = []
    for name in panels:
        panel = getattr(bpy.types, name)
        panel.draw(type("P", (), {"layout": _FakeLayout(log, folded)})(), bpy.context)
    return log


def test_panels_draw_settings_state_and_buttons(addon_module_name, bpy_module):
    bpy = bpy_module
    log = _draw_all(bpy)
    props = {entry[1] for entry in log if entry[0] == "prop"}
    assert {"capture_dir", "units", "armature", "algorithm", "likelihood", "preset", "particles", "iterations", "seed",
            "backend", "background", "smoothing_hz", "use_frame_range", "frame_start", "frame_end",
            "output_dir"} <= props
    ops = {entry[1] for entry in log if entry[0] == "operator"}
    assert ops == {"mocap.import_capture", "mocap.check_subject", "mocap.track", "mocap.export_fbx",
                   "mocap.export_bvh"}
    assert not any(entry[0] == "progress" for entry in log)

    # A run in progress with an imported capture, a checked rig and an error to show.
    cam = bpy.data.objects.new("cam1", bpy.data.cameras.new("cam1"))
    cam["mocap_resolution"] = [640, 480]
    coll = bpy.data.collections.new("Mocap Cameras")
    bpy.context.scene.collection.children.link(coll)
    coll.objects.link(cam)
    m = bpy.context.scene.mocap
    m.capture_frames, m.subject_checked, m.subject_dofs, m.subject_preset = 40, True, 30, "cmu"
    m.is_tracking, m.progress, m.frames_solved, m.frames_total = True, 0.25, 10, 40
    m.status, m.last_error = "Tracking frame 10/40", "x" * 300
    log = _draw_all(bpy)
    labels = [entry[1] for entry in log if entry[0] == "label"]
    assert any("1 cameras, 40 frames" in t for t in labels)
    assert any(t.startswith("cam1") and "640x480" in t for t in labels)
    assert "30 DOF, preset: cmu" in labels
    assert any("Esc to cancel" in t for t in labels)
    assert ("progress", pytest.approx(0.25), "10/40 frames") in log
    assert sum(len(t) for t in labels if set(t) == {"x"}) == 300  # the long error is wrapped, not cut


def _labels(log):
    return [entry[1] for entry in log if entry[0] == "label"]


def test_subject_panel_shows_the_armature_that_will_be_tracked(addon_module_name, bpy_module):
    """The Armature field stayed empty while tracking used the scene's armature: now the panel names the one that
    will be tracked, the first step that uses it fills the field, and several armatures ask for a pick."""
    bpy = bpy_module
    subject = ("MOCAP_PT_subject",)
    m = bpy.context.scene.mocap
    assert any("No armature in the scene" in t for t in _labels(_draw_all(bpy, panels=subject)))
    arm = build_armature(bpy, "cmu_mb_rest.json", name="Performer")
    assert m.armature is None
    assert "Tracks Performer, the scene's only armature" in _labels(_draw_all(bpy, panels=subject))
    _skin_boxes(bpy, arm)
    assert bpy.ops.mocap.check_subject() == {"FINISHED"}
    assert m.armature == arm  # the checked rig fills the field
    assert not any(t.startswith("Tracks ") for t in _labels(_draw_all(bpy, panels=subject)))
    other = build_armature(bpy, "cmu_mb_rest.json", name="Performer_actor")  # e.g. Apply to a Copy
    setup = _module(addon_module_name, "operators.setup_subject")
    assert setup.subject_armature(bpy.context) == arm  # the field, not "the scene's only one", decides
    m.armature = None  # several and none picked: the panel asks before Track would stop on it
    text = " ".join(_labels(_draw_all(bpy, panels=subject)))
    assert "2 armatures in the scene (Performer, Performer_actor): pick the one to track" in text
    with pytest.raises(RuntimeError, match="expected exactly one armature .*pick it in the Subject panel"):
        bpy.ops.mocap.check_subject()
    m.armature = other
    assert not any("pick the one" in t for t in _labels(_draw_all(bpy, panels=subject)))


def test_calibrated_proportions_fold_under_one_summary_line(addon_module_name, bpy_module):
    """After Calibrate Actor a dozen lines of lengths pushed the Track panel out of view: they are folded under the
    height's line until the user opens them."""
    bpy = bpy_module
    m = bpy.context.scene.mocap
    m.subject_checked, m.subject_dofs, m.subject_preset = True, 30, "cmu"
    lines = ["height 1.742 m (rig 1.800 m)"] + [f"segment {i} {30 + i:.1f} cm (rig 31.0 cm, x0.9{i})"
                                                for i in range(11)]
    before = _labels(_draw_all(bpy, folded=True, panels=("MOCAP_PT_subject",)))
    m.actor_file, m.actor_summary = "/somewhere/actor.json", "\n".join(lines)
    log = _draw_all(bpy, folded=True, panels=("MOCAP_PT_subject",))
    folded = _labels(log)
    assert ("panel", "MOCAP_actor_summary", True) in log
    assert "Actor 1.742 m (rig 1.800 m)" in folded  # short enough for the sidebar's width
    assert not any(line in folded for line in lines)
    assert len(folded) == len(before) + 1  # one line for the whole calibration while folded
    opened = _labels(_draw_all(bpy, panels=("MOCAP_PT_subject",)))
    assert all(line in opened for line in lines)


# ----------------------------------------------------------------------------- check rig
def _skin_boxes(bpy, arm):
    """A mesh of one small box per bone, each rigidly weighted to its bone."""
    verts, faces = [], []
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3) * 0.02
    quads = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    names = []
    for bone in arm.data.bones:
        c = (np.array(bone.head_local) + np.array(bone.tail_local)) / 2
        base = len(verts)
        verts += [tuple(c + k) for k in corners]
        faces += [tuple(base + i for i in q) for q in quads]
        names.append(bone.name)
    mesh = bpy.data.meshes.new("Skin")
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new("Skin", mesh)
    bpy.context.scene.collection.objects.link(obj)
    for i, name in enumerate(names):
        obj.vertex_groups.new(name=name).add(list(range(8 * i, 8 * i + 8)), 1.0, "REPLACE")
    obj.modifiers.new("Armature", "ARMATURE").object = arm
    return obj


def test_check_rig_reports_dof_and_preset(addon_module_name, bpy_module):
    bpy = bpy_module
    arm = build_armature(bpy, "cmu_mb_rest.json")
    _skin_boxes(bpy, arm)
    assert bpy.ops.mocap.check_subject() == {"FINISHED"}  # the scene's only armature is picked
    m = bpy.context.scene.mocap
    assert (m.subject_dofs, m.subject_preset, m.subject_problems) == (30, "cmu", "")


def test_check_rig_names_missing_bones_and_missing_skin(addon_module_name, bpy_module):
    bpy = bpy_module
    arm = build_armature(bpy, "cmu_mb_rest.json")
    with pytest.raises(RuntimeError, match="no mesh is skinned"):
        bpy.ops.mocap.check_subject()
    _skin_boxes(bpy, arm)
    arm.data.bones["LeftForeArm"].name = "elbow_thing"
    bpy.context.scene.mocap.armature = arm
    with pytest.raises(RuntimeError, match="missing bones: .*LeftForeArm"):
        bpy.ops.mocap.check_subject()
    m = bpy.context.scene.mocap
    assert m.subject_dofs == 0 and "LeftForeArm" in m.subject_problems


# ----------------------------------------------------------------------------- track
Estimate = namedtuple("Estimate", "frame pose joints energy seconds evaluations")


class FakeSession:
    """The TrackSession interface, solving nothing: frame f's 'pose' moves the armature to x = f / 10."""

    last = None
    fail_at = None  # index of the frame whose solve raises
    block_at = None  # index of the frame whose solve waits for `release`

    def __init__(self, scene, armature_obj, capture_dir, out_dir, settings=None, frames=None, resume=False,
                 log=None, units=None, step=None, smooth_hz=None, foot_lock=None, foot_lock_speed=None):
        FakeSession.last = self
        self.step = step or (lambda text, fraction: None)
        self.args = dict(capture_dir=capture_dir, out_dir=out_dir, settings=settings, frames=frames, resume=resume,
                         units=units, smooth_hz=smooth_hz)
        self.scene, self.armature = scene, armature_obj
        self.frames = list(frames) if frames is not None else [0, 1, 2]
        self.n_total = len(self.frames)
        self.solved, self.keyed, self.key_threads = [], [], set()
        if resume:  # an earlier run solved the first two frames
            self.solved, self.frames = self.frames[:2], self.frames[2:]
        self.finished, self.cancelled = None, False
        self.release, self.blocked = threading.Event(), threading.Event()
        if log:
            log("fake session ready")

    def solve_next(self):
        index = len(self.solved) - (self.n_total - len(self.frames))
        if self.cancelled or index >= len(self.frames):
            return None
        if index == self.fail_at:
            raise RuntimeError("boom: the likelihood exploded")
        if index == self.block_at:
            self.blocked.set()
            assert self.release.wait(10)
        if index == 0:  # the real session's one-off preparation, before the first frame
            self.step("fake preparation", 0.0)
            self.step("fake preparation", 0.5)
            self.step(None, 1.0)
        frame = self.frames[index]
        self.solved.append(frame)
        return Estimate(frame, np.array([frame / 10.0]), np.zeros((1, 3)), 1.0 / (1 + frame), 0.01, 3000)

    def key(self, estimate):
        self.key_threads.add(threading.current_thread().name)
        self.armature.location = (float(estimate.pose[0]), 0.0, 0.0)
        self.armature.keyframe_insert("location", frame=estimate.frame + self.scene.frame_start)
        self.keyed.append(estimate.frame)

    def key_all(self):
        for frame in self.solved:
            self.key(Estimate(frame, np.array([frame / 10.0]), None, 0.0, 0.0, 0))

    def cancel(self):
        self.cancelled = True

    def finish(self, export=True):
        self.finished = {"export": export, "frames": list(self.keyed)}
        return self.finished


@pytest.fixture
def fake_track(addon_module_name, bpy_module, monkeypatch, tmp_path):
    track = _module(addon_module_name, "operators.track")
    monkeypatch.setattr(track, "TrackSession", FakeSession)
    monkeypatch.setattr(FakeSession, "fail_at", None)
    monkeypatch.setattr(FakeSession, "block_at", None)
    FakeSession.last = None
    bpy = bpy_module
    arm = build_armature(bpy, "cmu_mb_rest.json", name="Performer")
    m = bpy.context.scene.mocap
    m.capture_dir, m.output_dir = str(tmp_path / "capture"), str(tmp_path / "out")
    bpy.context.scene.frame_start = 1
    compat = _module(addon_module_name, "addon.anim_compat")
    return bpy, track, arm, compat, tmp_path


def test_track_execute_keys_every_frame_and_finishes(fake_track):
    bpy, _, arm, compat, tmp_path = fake_track
    m = bpy.context.scene.mocap
    m.algorithm, m.likelihood, m.particles, m.iterations, m.seed, m.backend = "apf", "silhch+color", 50, 4, 7, "numpy"
    m.use_frame_range, m.frame_start, m.frame_end = True, 2, 4
    assert m.smoothing_hz == 8.0  # the default cut-off (core/tracking/smoothing.py)
    m.smoothing_hz = 5.5
    assert bpy.ops.mocap.track() == {"FINISHED"}

    session = FakeSession.last
    assert session.args["smooth_hz"] == 5.5
    s = session.args["settings"]
    assert (s.algorithm, s.likelihood, s.particles, s.iterations, s.seed, s.backend) == (
        "apf", "silhch+color", 50, 4, 7, "numpy")
    assert session.args["frames"] == range(2, 5)
    assert session.args["out_dir"] == tmp_path / "out" and session.args["capture_dir"] == tmp_path / "capture"
    assert session.armature == arm
    assert session.keyed == [2, 3, 4] and session.key_threads == {threading.main_thread().name}
    assert session.finished == {"export": True, "frames": [2, 3, 4]}
    assert compat.keyed_frames(arm, "location") == [3.0, 4.0, 5.0]  # capture frame + scene start
    assert (m.frames_solved, m.frames_total, m.progress, m.is_tracking) == (3, 3, pytest.approx(1.0), False)
    assert m.last_output == str(tmp_path / "out") and m.last_error == ""
    assert m.seconds_per_frame == pytest.approx(0.01)
    assert m.backend_used.startswith("numpy (")  # the Track panel shows which backend ran, and why
    assert s.fine_refine  # the full preset's local fit on finer silhouettes
    labels = [entry[1] for entry in _draw_all(bpy) if entry[0] == "label"]
    assert any(t.startswith("Using: numpy") for t in labels)


def test_preview_preset_sets_the_budget_and_the_local_fit_resolution(fake_track):
    bpy = fake_track[0]
    m = bpy.context.scene.mocap
    m.preset = "preview"
    assert (m.particles, m.iterations) == (50, 4)  # shown in the panel, still editable
    m.iterations = 6
    s = m.tracking_settings()
    assert (s.particles, s.iterations, s.fine_refine) == (50, 6, False)
    m.preset = "full"
    assert (m.particles, m.iterations, m.tracking_settings().fine_refine) == (200, 15, True)


def test_track_with_gpu_asked_for_and_no_gpu_names_the_fix(fake_track, monkeypatch, addon_module_name):
    bpy = fake_track[0]
    choice = _module(addon_module_name, "operators.backend_choice")
    monkeypatch.setattr(choice, "_probe_result", {"ok": False, "error": "libEGL.so.1: cannot open"})
    m = bpy.context.scene.mocap
    m.backend = "gpu"
    with pytest.raises(RuntimeError, match="apt-get install"):
        bpy.ops.mocap.track()
    assert FakeSession.last is None and not m.is_tracking
    assert "libEGL" in m.last_error and "apt-get install" in m.last_error and "\n" not in m.last_error
    m.backend = "auto"  # auto falls back instead, and says why
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert FakeSession.last.args["settings"].backend in ("fast", "numpy") and "no usable GPU" in m.backend_used


def test_status_is_one_line_per_frame_and_the_preparation_its_own_step(fake_track):
    """Issue 14: the first message stayed appended to every later frame's status, and the one-off
    preparation (about 45 s on a new rig) showed no progress. Now: the preparation is a step with its
    percentage and its own bar; each frame's line is 'Frame k of n, s/frame, time left' and nothing else."""
    import re

    bpy, track, _arm, _compat, tmp_path = fake_track
    m = bpy.context.scene.mocap
    job = track.TrackJob()
    session = FakeSession(bpy.context.scene, _arm, tmp_path, tmp_path, frames=[0, 1, 2, 3],
                          log=job.report_progress, step=job.report_step)
    job._attach(session)
    m.is_tracking = True
    shown = []

    def show():
        job.drain()
        track.MOCAP_OT_track._show(None, bpy.context, job)
        shown.append((m.status, m.preparing, round(m.progress, 3)))
        log = _draw_all(bpy)
        return [entry for entry in log if entry[0] == "progress"]

    show()
    assert shown[-1][0] == "Frame 1 of 4: solving (the first frame searches the whole body) - fake session ready"
    job.report_step("anatomical prior and dynamics for this rig", 0.4)
    bars = show()
    assert shown[-1] == ("Preparing (once per rig): anatomical prior and dynamics for this rig, 40 %", True, 0.4)
    assert bars == [("progress", pytest.approx(0.4), "Preparing 40 %")]
    for k in range(1, 5):
        estimate = session.solve_next()
        job.queue.put(("frame", estimate))
        bars = show()
        status, preparing, progress = shown[-1]
        if k == 1:
            assert status == "Frame 1 of 4, 0.0 s (the first frame's whole-body search); time left after frame 2"
        else:
            assert re.fullmatch(rf"Frame {k} of 4, 0\.0 s/frame, about \d+ s left", status), status
        assert not preparing and progress == pytest.approx(k / 4)
        assert bars == [("progress", pytest.approx(k / 4), f"{k}/4 frames")]
    assert shown[-1][0] == "Frame 4 of 4, 0.0 s/frame, about 0 s left"
    # a message sent later is shown with the next line only, then dropped
    job.report_progress("limb search: left arm")
    show()
    assert shown[-1][0].endswith(" - limb search: left arm")
    m.is_tracking = False


def test_time_left_uses_the_recent_frames_not_the_first_search(fake_track):
    _bpy, track, _arm, _compat, tmp_path = fake_track
    job = track.TrackJob()
    job._attach(FakeSession(None, None, tmp_path, tmp_path, frames=list(range(10))))
    job.estimates.append(Estimate(0, None, None, 0.0, 60.0, 0))
    assert track._status_line(job) == ("Frame 1 of 10, 60.0 s (the first frame's whole-body search); "
                                       "time left after frame 2")  # not 9 x 60 s
    job.estimates.clear()
    for frame, seconds in enumerate((60.0, 2.0, 4.0)):
        job.estimates.append(Estimate(frame, None, None, 0.0, seconds, 0))
    assert job.seconds_left == pytest.approx(7 * 3.0)
    assert track._status_line(job) == "Frame 3 of 10, 3.0 s/frame, about 21 s left"  # 7 x 3 s, not 7 x 22 s
    job.estimates.append(Estimate(3, None, None, 0.0, 100.0, 0))
    assert track._status_line(job) == "Frame 4 of 10, 35.3 s/frame, about 3 min 32 s left"  # 6 x (2+4+100)/3


def test_session_reports_its_preparation_as_steps(monkeypatch, tmp_path):
    """The real TrackSession: the motion models' progress arrives as (text, fraction) steps, rising, then
    (None, 1.0) once the tracker is built; the cheap motion-library callback is real, the model fit faked."""
    from markerless_mocap.core.tracking import motion_library
    from markerless_mocap.operators import track_session

    calls = []

    def fake_build(body, capture_folder, fps, seed=0, progress=None):
        for i in range(3):
            progress(i / 3, f"mapping motion clip {i + 1} of 3 onto the rig")
        progress(0.9, "fitting the anatomical prior and the dynamics")
        raise _Stop

    class _Stop(Exception):
        pass

    session = track_session.TrackSession.__new__(track_session.TrackSession)
    session.tracker, session.prior = None, None
    session.body, session.character = None, None
    session.capture_dir, session.settings = tmp_path, type("S", (), {"seed": 0})()
    session.capture = type("C", (), {"frames": type("F", (), {"fps": 30.0})()})()
    session.step = lambda text, fraction: calls.append((text, fraction))
    monkeypatch.setattr(track_session, "build_motion_models", fake_build)
    with pytest.raises(_Stop):
        session.prepare()
    fractions = [f for _t, f in calls]
    assert calls[0][0].startswith("anatomical prior and dynamics") and fractions == sorted(fractions)
    assert calls[-1] == ("fitting the anatomical prior and the dynamics", pytest.approx(0.85 * 0.9))
    assert motion_library.build_motion_models.__code__.co_varnames.count("progress") == 1


def test_track_resume_rekeys_earlier_frames_and_counts_them(fake_track):
    bpy, _, arm, compat, _ = fake_track
    m = bpy.context.scene.mocap
    m.resume = True
    assert bpy.ops.mocap.track() == {"FINISHED"}
    session = FakeSession.last
    assert session.args["resume"] is True and session.solved == [0, 1, 2]
    assert session.keyed == [0, 1, 2]  # two re-keyed from the earlier run, one solved now
    assert compat.keyed_frames(arm, "location") == [1.0, 2.0, 3.0]
    assert (m.frames_solved, m.frames_total, m.progress) == (3, 3, pytest.approx(1.0))


def test_track_reports_worker_errors_and_keeps_solved_frames(fake_track, monkeypatch):
    bpy, _, arm, compat, _ = fake_track
    monkeypatch.setattr(FakeSession, "fail_at", 1)
    with pytest.raises(RuntimeError, match="boom: the likelihood exploded.*This is a bug in Markerless Mocap"):
        bpy.ops.mocap.track()
    session = FakeSession.last
    assert session.keyed == [0] and session.finished is not None
    assert compat.keyed_frames(arm, "location") == [1.0]
    m = bpy.context.scene.mocap
    assert "boom" in m.last_error and "bug" in m.last_error and not m.is_tracking


def test_a_bad_frame_of_footage_is_the_users_error_not_a_bug(fake_track, monkeypatch, addon_module_name):
    """An InputError while solving (a video that ends early) reads as the user's to fix: its message alone."""
    bpy, _, arm, compat, _ = fake_track
    frames = _module(addon_module_name, "core.capture.frames")
    message = "camera 'cam2' (cam2.mp4) has only 1 frames (0-0): track frames 0-0 at most"
    solve = FakeSession.solve_next

    def solve_next(self):
        if self.solved:
            raise frames.FrameSourceError(message)
        return solve(self)

    monkeypatch.setattr(FakeSession, "solve_next", solve_next)
    with pytest.raises(RuntimeError, match="cam2.mp4"):
        bpy.ops.mocap.track()
    m = bpy.context.scene.mocap
    assert m.last_error == message and "bug" not in m.status
    assert FakeSession.last.keyed == [0] and compat.keyed_frames(arm, "location") == [1.0]


def test_track_setup_errors_name_the_fix(fake_track):
    bpy = fake_track[0]
    m = bpy.context.scene.mocap
    m.capture_dir = ""
    with pytest.raises(RuntimeError, match="No capture folder"):
        bpy.ops.mocap.track()
    m.capture_dir, m.output_dir = "/somewhere", ""
    with pytest.raises(RuntimeError, match="No output folder"):
        bpy.ops.mocap.track()
    m.output_dir, m.use_frame_range, m.frame_start, m.frame_end = "/out", True, 5, 3
    with pytest.raises(RuntimeError, match="before the first"):
        bpy.ops.mocap.track()
    assert FakeSession.last is None and not m.is_tracking


class _FinishedTake(FakeSession):
    """A take whose every frame an earlier run solved; finishing it smooths again (joints_raw written) or not."""

    smooths = True

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.solved, self.frames = self.solved + self.frames, []

    def finish(self, export=True):
        super().finish(export)
        return {**self.finished, **({"joints_raw": "joints_raw.npz"} if self.smooths else {})}


@pytest.mark.parametrize("smooths", [True, False])
def test_a_resmooth_says_what_it_did_in_the_status_bar(fake_track, monkeypatch, smooths):
    """Resume on a finished take with another Smoothing: nothing is solved, and the status bar said 'Tracked 0
    frames'; it says the take was smoothed again (or rewritten unsmoothed) and that every frame was tracked."""
    from types import SimpleNamespace

    bpy, track, _arm, _compat, tmp_path = fake_track
    monkeypatch.setattr(track, "TrackSession", _FinishedTake)
    monkeypatch.setattr(_FinishedTake, "smooths", smooths)
    m = bpy.context.scene.mocap
    m.resume, m.smoothing_hz = True, 3.0 if smooths else 0.0
    job = track.TrackJob()
    job.out_dir = track.output_folder(bpy.context)  # as the operator's start does
    job.run_inline(track.build_session(bpy.context))
    reports = []
    operator = SimpleNamespace(report=lambda level, text: reports.append((level, text)),
                               _show=lambda context, j: track.MOCAP_OT_track._show(None, context, j))
    assert track.MOCAP_OT_track._end(operator, bpy.context, job) == {"FINISHED"}
    [(level, text)] = reports
    done = "Smoothed again at 3 Hz" if smooths else "Rewritten as solved, unsmoothed"
    assert level == {"INFO"} and text == f"{done}: all 3 frames were already tracked; results in {tmp_path / 'out'}"
    assert "Tracked 0" not in m.status and m.frames_solved == 3
    results = _labels(_draw_all(bpy, panels=("MOCAP_PT_results",)))
    assert "3 frames" in results  # no '0.0 s/frame': no frame was timed


def _drain_until(job, condition, timeout=10.0):
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "worker did not get there in time"
        job.drain()
        time.sleep(0.005)


def test_threaded_job_cancel_keeps_solved_frames(fake_track, monkeypatch):
    """What the modal operator does: worker thread solves, main thread drains/keys, Esc cancels."""
    bpy, track, arm, compat, _ = fake_track
    monkeypatch.setattr(FakeSession, "block_at", 1)
    job = track.TrackJob()
    session = track.build_session(bpy.context, log=job.report_progress)
    job.start(session)
    _drain_until(job, lambda: len(job.estimates) == 1 and session.blocked.is_set())
    assert job.status == ""  # the session's first message went with the first frame (it used to stick)
    assert job.fraction == pytest.approx(1 / 3)
    job.request_cancel()  # Esc while frame 1 is being solved: it completes, frame 2 never starts
    session.release.set()
    _drain_until(job, lambda: job.done)
    assert job.finish() == {"export": True, "frames": [0, 1]}
    assert session.solved == [0, 1] and session.keyed == [0, 1]
    assert session.key_threads == {threading.main_thread().name}
    assert job.cancelled and job.error is None
    assert compat.keyed_frames(arm, "location") == [1.0, 2.0]
    assert not job.thread.is_alive()


def test_threaded_job_reports_worker_error(fake_track, monkeypatch):
    bpy, track, _, _, _ = fake_track
    monkeypatch.setattr(FakeSession, "fail_at", 2)
    job = track.TrackJob()
    job.start(track.build_session(bpy.context))
    _drain_until(job, lambda: job.done)
    assert job.error.startswith("Tracking failed with an internal error (RuntimeError: boom: the likelihood "
                                "exploded). This is a bug in Markerless Mocap")
    assert [e.frame for e in job.estimates] == [0, 1]
    job.finish()
    assert FakeSession.last.finished == {"export": True, "frames": [0, 1]}


def test_a_blend_saved_mid_run_opens_ready_to_track(addon_module_name, bpy_module, tmp_path):
    bpy = bpy_module
    bpy.context.scene.mocap.is_tracking = True
    path = tmp_path / "saved_while_tracking.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    m = bpy.context.scene.mocap
    assert not m.is_tracking and "did not finish" in m.status
    assert bpy.ops.mocap.track.poll()


# ----------------------------------------------------------------------------- Run On: chunks elsewhere
def test_run_on_shows_its_settings_and_a_running_batch_its_chunks(addon_module_name, bpy_module):
    bpy = bpy_module
    m = bpy.context.scene.mocap
    assert m.run_on == "this"
    assert not {"local_workers", "scheduler_address", "chunk_frames"} & {e[1] for e in _draw_all(bpy) if e[0] == "prop"}
    m.run_on = "local"
    props = {e[1] for e in _draw_all(bpy) if e[0] == "prop"}
    assert {"run_on", "batch_scope", "local_workers", "chunk_frames"} <= props and "scheduler_address" not in props
    m.run_on, m.batch_scope = "cluster", "folder"
    props = {e[1] for e in _draw_all(bpy) if e[0] == "prop"}
    assert {"scheduler_address", "worker_command", "batch_folder", "chunk_frames"} <= props
    assert "local_workers" not in props
    # a batch running: its chunks in the bar, a Cancel button (no modal operator to take Esc)
    m.is_tracking, m.batch_dir, m.chunks_done, m.chunks_total, m.progress = True, "batch_out", 3, 8, 3 / 8
    log = _draw_all(bpy)
    assert ("progress", pytest.approx(3 / 8), "3/8 chunks") in log
    assert ("operator", "mocap.cancel_batch") in log
    assert not any("Esc to cancel" in t for t in _labels(log))


def test_batch_setup_errors_name_the_fix(addon_module_name, bpy_module, tmp_path):
    bpy = bpy_module
    build_armature(bpy, "cmu_mb_rest.json", name="Performer")
    m = bpy.context.scene.mocap
    m.output_dir, m.capture_dir = str(tmp_path / "out"), str(tmp_path / "capture")
    m.run_on = "cluster"
    with pytest.raises(RuntimeError, match="No scheduler address"):
        bpy.ops.mocap.track()
    assert not m.is_tracking and not m.batch_dir and "tcp://" in m.last_error
    m.run_on, m.batch_scope, m.batch_folder = "local", "folder", str(tmp_path / "captures")
    (tmp_path / "captures" / "not_a_capture").mkdir(parents=True)
    with pytest.raises(RuntimeError, match="no capture in .*captures"):
        bpy.ops.mocap.track()
    assert not m.is_tracking
    track_batch = _module(addon_module_name, "operators.track_batch")
    assert [track_batch.take_name(n) for n in ("walk 01", "/x/day2.take-07/", "__", "_a")] == [
        "walk_01", "day2.take-07", "take", "a"]


def test_a_folder_sent_to_a_cluster_sends_each_capture_with_the_panels_settings(addon_module_name, bpy_module,
                                                                               tmp_path, monkeypatch):
    """What the Track button hands the batch runner for Run On = Scheduler and a folder of captures, and a batch
    that could not start (exit 2 before any progress) reported with its log's words."""
    bpy = bpy_module
    build_armature(bpy, "cmu_mb_rest.json", name="Performer")
    captures = tmp_path / "day 2"
    for name in ("take 01", "take-02", "_chunks", "notes"):
        (captures / name).mkdir(parents=True)
    for name in ("take 01", "take-02"):
        (captures / name / "calibration.toml").write_text("")
    m = bpy.context.scene.mocap
    m.output_dir = str(tmp_path / "out")
    m.run_on, m.scheduler_address, m.worker_command = "cluster", " tcp://10.0.0.5:8786 ", "/opt/b/blender -b"
    m.batch_scope, m.batch_folder, m.chunk_frames = "folder", str(captures), 450
    m.preset, m.seed, m.refine, m.smoothing_hz = "preview", 3, False, 6.5
    m.foot_lock, m.foot_lock_speed = False, 0.3
    cmd_batch = _module(addon_module_name, "operators.cmd_batch")
    track_batch = _module(addon_module_name, "operators.track_batch")
    sent = {}

    def fake_launch(takes, out_dir, **kwargs):
        sent.update(kwargs, takes=takes, out_dir=out_dir)
        (out_dir / "batch.log").write_text("markerless_mocap batch: take 'take_01': the capture has no videos/\n")
        return _EndedProcess(2)

    monkeypatch.setattr(cmd_batch, "launch_batch", fake_launch)
    assert bpy.ops.mocap.track() == {"FINISHED"}
    out = tmp_path / "out"
    assert sent["out_dir"] == out and sent["scheduler"] == "tcp://10.0.0.5:8786" and sent["workers"] is None
    assert sent["chunk_frames"] == 450
    assert [t["name"] for t in sent["takes"]] == ["take_01", "take-02"]
    assert [t["capture"] for t in sent["takes"]] == [str(captures / "take 01"), str(captures / "take-02")]
    assert {t["armature"] for t in sent["takes"]} == {"Performer"} and "frames" not in sent["takes"][0]
    subject = Path(sent["takes"][0]["scene"])
    assert subject.is_file() and subject.parent == out  # the scene as it is now, where the workers read it
    choices = sent["settings"]
    assert (choices["preset"], choices["particles"], choices["iterations"], choices["seed"], choices["refine"]) == (
        "preview", 50, 4, 3, "none")
    assert sent["extra_args"] == ["--smooth", "6.5", "--no-foot-lock", "--foot-lock-speed", "0.3", "--worker-command",
                                  "/opt/b/blender -b"]  # the panel's smoothing and foot locking reach the stitch
    assert sent["command"][-2:] == ["-m", "markerless_mocap"]  # bpy is a module here: this Python runs it
    assert m.is_tracking and m.batch_dir == str(out)
    while bpy.context.scene.name in track_batch._RUNS:
        track_batch.poll(bpy.context.scene.name)
    assert m.last_error.startswith("The batch did not run: markerless_mocap batch: take 'take_01': the capture")
    assert not m.is_tracking and not m.batch_dir


class _EndedProcess:
    def __init__(self, code):
        self.returncode, self.polls = None, 0
        self._code = code

    def poll(self):  # running on the first poll, ended on the second
        self.polls += 1
        if self.polls > 1:
            self.returncode = self._code
        return self.returncode


def _write_progress(folder, state, takes, chunks=(2, 2)):
    import json

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "batch-progress.json").write_text(json.dumps({
        "state": state, "started": 0, "updated": 0, "error": None,
        "total": {"chunks_done": chunks[0], "chunks_total": chunks[1], "frames_done": 5, "frames_total": 5,
                  "seconds_left": 12.0},
        "takes": takes}))


def test_a_finished_batch_is_keyed_from_its_stitched_poses(addon_module_name, bpy_module, tmp_path):
    """The timer's side without processes: progress shown while the batch runs, then the result folder's poses.npz
    keyed on the armature (capture frame + the scene's start, as Track keys), and a result of another rig refused
    with its reason."""
    from rig_helpers import load_subject

    bpy = bpy_module
    arm, _mesh = load_subject(bpy)
    scene = bpy.context.scene
    scene.frame_start = 1
    track_batch = _module(addon_module_name, "operators.track_batch")
    compat = _module(addon_module_name, "addon.anim_compat")
    body = _module(addon_module_name, "addon.scene_bridge").body_from_blender(arm, None, scene)
    rng = np.random.default_rng(0)
    poses = np.repeat(body.default_pose()[None], 5, axis=0)
    poses[:, body.translation_dofs] += rng.normal(0, 0.05, (5, len(body.translation_dofs)))
    out = tmp_path / "batch"
    result = out / "walk"
    result.mkdir(parents=True)
    np.savez(result / "poses.npz", dof_names=np.array(body.dof_names), frames=np.arange(3, 8), poses=poses)

    def send(take_state, process, error=None):
        run = track_batch.BatchRun(scene.name, arm.name, out, process, ["walk"], frame_offset=1)
        track_batch._RUNS[scene.name] = run
        scene.mocap.batch_dir, scene.mocap.is_tracking = str(out), True
        _write_progress(out, "running", [{"name": "walk", "state": "running", "chunks_done": 1, "chunks_total": 2,
                                          "frames": [3, 7], "result": None, "error": None}], chunks=(1, 2))
        assert track_batch.poll(scene.name) == track_batch.POLL_SECONDS
        m = scene.mocap
        assert (m.chunks_done, m.chunks_total, m.progress) == (1, 2, pytest.approx(0.5))
        assert m.status == "Running: chunk 1 of 2, about 12 s left" and m.is_tracking
        _write_progress(out, "done", [{"name": "walk", "state": take_state, "chunks_done": 2, "chunks_total": 2,
                                       "frames": [3, 7], "result": str(result), "error": error}])
        assert track_batch.poll(scene.name) is None  # ended: the timer stops
        assert scene.name not in track_batch._RUNS and not m.is_tracking and not m.batch_dir
        return m

    m = send("done", _EndedProcess(0))
    assert m.last_error == "" and m.last_output == str(result)
    assert m.status.startswith("Tracked 5 frames in 2 chunks") and str(result) in m.status
    assert "landmarks left out" not in m.status  # no report.json here: nothing to say
    views = {str(f): ["cam2"] for f in range(3, 8)}  # the stitched report: cam2's landmarks left out on frames 3-7
    (result / "report.json").write_text(json.dumps({"views_shared": views}))
    m = send("done", _EndedProcess(0))
    said = _module(addon_module_name, "core.results.views_without_landmarks").views_without_landmarks_message(
        {"views_shared": views})
    assert m.status.endswith(said) and "cam2 on frames 3-7" in m.status
    (result / "report.json").unlink()
    assert compat.keyed_frame_range(arm) == (4, 8) and (scene.frame_start, scene.frame_end) == (4, 8)
    root = arm.pose.bones[body.skeleton.bone_names[body.root_bone]]
    expected = body.local_bases(poses)[:, body.root_bone, :3, 3]
    for i, frame in enumerate(range(4, 9)):
        scene.frame_set(frame)
        assert np.allclose(np.array(root.location), expected[i], atol=1e-5), frame

    np.savez(result / "poses.npz", dof_names=np.array(body.dof_names[:-1]), frames=np.arange(3, 8),
             poses=poses[:, :-1])
    m = send("done", _EndedProcess(0))
    assert "tracked with another rig" in m.last_error and "not keyed" in m.status
    m = send("failed", _EndedProcess(1), error="take 'walk': chunk 000000-000004: the capture has no frame 4")
    assert m.last_error == "take 'walk': chunk 000000-000004: the capture has no frame 4"
    assert "none keyed" in m.status and not m.is_tracking


@pytest.mark.slow
def test_track_on_local_processes_keys_the_stitched_take(addon_module_name, bpy_module, tmp_path):
    """The Track button with Run On = Local Processes: the take goes to `batch` in a process of its own (one chunk
    worker), the panel shows the chunks as they finish without waiting on them, and the stitched take is keyed on
    the armature when it is done."""
    from conftest import SAMPLE_SCENES

    bpy = bpy_module
    walk = SAMPLE_SCENES / "walk"
    bpy.ops.wm.open_mainfile(filepath=str(walk / "subject.blend"))
    scene = bpy.context.scene
    m = scene.mocap
    m.capture_dir, m.output_dir = str(walk), str(tmp_path / "out")
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 11
    m.particles, m.iterations, m.refine = 20, 3, False
    m.run_on, m.local_workers, m.chunk_frames = "local", 1, 10  # 2 chunks: keeps 0-5 and 6-11
    track_batch = _module(addon_module_name, "operators.track_batch")
    compat = _module(addon_module_name, "addon.anim_compat")
    arm = next(o for o in scene.objects if o.type == "ARMATURE")

    started = time.monotonic()
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert time.monotonic() - started < 10  # it only starts the process
    assert m.is_tracking and m.batch_dir == str(tmp_path / "out") and "planning" in m.status
    assert not bpy.ops.mocap.track.poll()  # one run at a time
    seen = set()
    deadline = time.monotonic() + 900
    while scene.name in track_batch._RUNS:  # what the bpy.app.timers callback does (no event loop here)
        assert time.monotonic() < deadline, f"the batch did not end: {m.status}"
        track_batch.poll(scene.name)
        seen.add((m.chunks_done, m.chunks_total))
        time.sleep(0.5)
    log = (tmp_path / "out" / "batch.log").read_text()
    assert m.last_error == "", f"{m.last_error}\n{log[-3000:]}"
    assert (0, 2) in seen or (1, 2) in seen, seen  # the bar moved with the chunks
    result = tmp_path / "out" / "walk"
    assert m.last_output == str(result) and (m.chunks_done, m.chunks_total) == (2, 2)
    data = np.load(result / "poses.npz")
    assert list(data["frames"]) == list(range(12))
    assert {"joints.npz", "report.json", "animation.bvh", "tracked.blend"} <= {p.name for p in result.iterdir()}
    assert compat.keyed_frame_range(arm) == (scene.frame_start, scene.frame_start + 11)
    assert not m.is_tracking and bpy.ops.mocap.track.poll()


def test_the_status_says_the_take_was_smoothed_and_its_feet_locked(fake_track, monkeypatch):
    bpy, _, arm, compat, tmp_path = fake_track
    m = bpy.context.scene.mocap

    def finish(self, export=True):  # what the real session lists when it smoothed and pinned the take
        self.finished = {"joints": tmp_path / "j", "joints_raw": tmp_path / "r", "joints_unpinned": tmp_path / "u"}
        return self.finished

    monkeypatch.setattr(FakeSession, "finish", finish)
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert m.status.startswith("Tracked 3 frames, ") and m.status.endswith(" s/frame, smoothed at 8 Hz, feet locked")


def test_track_warns_where_a_views_landmarks_were_left_out(fake_track, monkeypatch, capfd):
    """A take whose report lists views without landmarks (someone in front of the actor) ends with a warning that
    names the views, the frames and the fix, not with the plain 'Tracked' line."""
    bpy, _, _, _, _ = fake_track
    shared = {str(f): ["cam1"] for f in range(10, 16)}
    monkeypatch.setattr(FakeSession, "writer", types.SimpleNamespace(info={"views_shared": shared}), raising=False)
    assert bpy.ops.mocap.track() == {"FINISHED"}
    out = capfd.readouterr()
    said = out.out + out.err
    assert "landmarks left out: cam1 on frames 10-15" in said and "--armature ACTOR --armature OTHER" in said
    monkeypatch.setattr(FakeSession, "writer", types.SimpleNamespace(info={}), raising=False)
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert "landmarks left out" not in "".join(capfd.readouterr())
