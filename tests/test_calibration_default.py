"""The actor's build by default (issue 43): `track` fits the actor's proportions first on a take of at least 20
frames unless told --no-calibrate; a shorter take and a resumed take tracked with the rig keep the rig; several
actors are each fitted, with their own saved calibrations and measured lengths. In Blender, Track does the same
with *Fit the Actor's Build* (on by default) and reuses a calibration made on the same capture. The calibration
itself is replaced by a recorder here: its accuracy is tests/test_actor_ui.py's and docs/actor-calibration.md's."""
import argparse
import importlib
import re
from pathlib import Path

import pytest

from scene_helpers import scene_dir

WALK = scene_dir("walk")  # 60 frames


def _args(out, *argv):
    from markerless_mocap.operators.cmd_track import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(["--capture", str(WALK), "--out", str(out), *argv])


@pytest.fixture
def recorded_calibrations(monkeypatch, tmp_path):
    """calibrate_actor replaced by a recorder of the frames it was given; load_actor by the path it was given."""
    from markerless_mocap.core.actor import actor_file
    from markerless_mocap.operators import actor_calibration

    class Calls(list):
        measured = []  # the measured lengths each call was given

    calls = Calls()

    def fake_calibrate(scene, armature, capture_dir, out_dir, settings=None, frames=None, measured=None, **_):
        calls.append(None if frames is None else list(frames))
        calls.measured.append(measured)
        return None, Path(out_dir) / "actor.json"

    monkeypatch.setattr(actor_calibration, "calibrate_actor", fake_calibrate)
    monkeypatch.setattr(actor_calibration, "describe", lambda fit: ["height 1.700 m (rig 1.700 m)"])
    monkeypatch.setattr(actor_file, "load_actor", lambda path: {"loaded": str(path)})
    return calls


def test_track_fits_the_actor_first_by_default_on_a_long_enough_take(recorded_calibrations, tmp_path, capsys):
    from markerless_mocap.operators.cmd_track import load_actor_option

    out = tmp_path / "r"
    # the whole 60-frame take, and a 30-frame range: fitted on their first 20 frames
    assert load_actor_option(_args(out), None, None) == {"loaded": str(out / "actor.json")}
    assert load_actor_option(_args(out, "--frames", "10-39"), None, None) is not None
    assert recorded_calibrations == [None, list(range(10, 30))]  # None: the session takes the take's first 20
    # a 12-frame take keeps the rig, and says so; --calibrate fits on it anyway
    assert load_actor_option(_args(out, "--frames", "0-11"), None, None) is None
    assert "the take has 12 frames, fewer than the 20" in capsys.readouterr().err
    assert load_actor_option(_args(out, "--frames", "0-11", "--calibrate"), None, None) is not None
    assert recorded_calibrations[-1] == list(range(12))
    # --no-calibrate: the rig; a measured length asks for a calibration, so not with --no-calibrate
    del recorded_calibrations[:]
    assert load_actor_option(_args(out, "--no-calibrate"), None, None) is None
    assert recorded_calibrations == []
    from markerless_mocap.core.errors import InputError

    with pytest.raises(InputError, match="--calibrate-measured applies to the actor calibration"):
        load_actor_option(_args(out, "--no-calibrate", "--calibrate-measured", "height=1.7"), None, None)
    with pytest.raises(SystemExit):  # argparse: one of --calibrate, --no-calibrate, --actor
        _args(out, "--calibrate", "--no-calibrate")


def test_a_resumed_take_keeps_the_body_it_was_tracked_with(recorded_calibrations, tmp_path):
    from markerless_mocap.operators.cmd_track import load_actor_option

    rig_run = tmp_path / "rig"
    rig_run.mkdir()
    (rig_run / "checkpoint.npz").write_bytes(b"")  # an earlier run tracked with the rig and was interrupted
    assert load_actor_option(_args(rig_run, "--resume"), None, None) is None
    fitted_run = tmp_path / "fitted"
    fitted_run.mkdir()
    (fitted_run / "checkpoint.npz").write_bytes(b"")
    (fitted_run / "actor.json").write_text("{}")
    assert load_actor_option(_args(fitted_run, "--resume"), None, None) == {"loaded": str(fitted_run / "actor.json")}
    fresh = tmp_path / "fresh"  # interrupted before its first frame was saved: fitted as a new take would be
    assert load_actor_option(_args(fresh, "--resume"), None, None) is not None
    assert recorded_calibrations == [None]


# ---- in Blender: Track with Fit the Actor's Build

def _blender(addon_module_name, bpy_module, monkeypatch, tmp_path):
    from rig_helpers import subject_blend_path
    from test_actor_ui import _fit
    from test_addon_ui import FakeSession

    mod = lambda name: importlib.import_module(f"{addon_module_name}.{name}")
    bpy = bpy_module

    class ActorSession(FakeSession):
        def __init__(self, *args, actor=None, **kwargs):
            super().__init__(*args, **kwargs)
            self.args["actor"] = actor

    monkeypatch.setattr(mod("operators.track"), "TrackSession", ActorSession)
    monkeypatch.setattr(FakeSession, "fail_at", None)
    monkeypatch.setattr(FakeSession, "block_at", None)
    bpy.ops.wm.open_mainfile(filepath=str(subject_blend_path()))
    arm = mod("addon.scene_bridge").find_armature(bpy.context.scene)
    body = mod("addon.scene_bridge").body_from_blender(arm, None, bpy.context.scene)
    fit = _fit(body, mod("core.actor.proportions"), mod("core.actor.landmark_fit"))
    calls = []

    def fake_calibrate(scene, armature, capture_dir, out_dir, settings=None, frames=None, **_):
        calls.append((Path(capture_dir).name, list(frames)))
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        path = mod("core.actor.actor_file").save_actor(Path(out_dir) / "actor.json", fit, subject_name=armature.name,
                                                       capture=Path(capture_dir).resolve())
        return fit, path

    monkeypatch.setattr(mod("operators.actor_calibration"), "calibrate_actor", fake_calibrate)
    m = bpy.context.scene.mocap
    m.capture_dir, m.output_dir = str(WALK), str(tmp_path / "out")
    return bpy, m, calls, ActorSession


@pytest.mark.bpy
def test_track_in_blender_fits_the_actor_first_and_reuses_the_fit(addon_module_name, bpy_module, monkeypatch,
                                                                    tmp_path):
    bpy, m, calls, session = _blender(addon_module_name, bpy_module, monkeypatch, tmp_path)
    assert m.fit_actor_build  # on by default
    m.use_frame_range, m.frame_start, m.frame_end, m.calibrate_frames = True, 5, 29, 20
    assert bpy.ops.mocap.track() == {"FINISHED"}, m.last_error
    assert calls == [("walk", list(range(5, 25)))]
    assert session.last.args["actor"]["height_m"] > 0 and m.use_actor  # tracked with the fit, which the panel shows
    assert bpy.ops.mocap.track() == {"FINISHED"}  # the same capture again: its calibration is reused
    assert len(calls) == 1 and session.last.args["actor"] is not None
    m.capture_dir = str(scene_dir("sit"))  # another capture: fitted again
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert [c[0] for c in calls] == ["walk", "sit"]
    # no capture there: no fit is tried (the real session's start names the problem; this one is a stand-in)
    m.capture_dir, m.use_frame_range = str(tmp_path / "nowhere"), False
    assert bpy.ops.mocap.track() == {"FINISHED"} and len(calls) == 2


@pytest.mark.bpy
@pytest.mark.parametrize("setting", ["short take", "switched off", "resumed"])
def test_track_in_blender_keeps_the_rig_when_it_should(addon_module_name, bpy_module, monkeypatch, tmp_path, setting):
    bpy, m, calls, session = _blender(addon_module_name, bpy_module, monkeypatch, tmp_path)
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 29
    if setting == "short take":
        m.frame_end = 18  # 19 frames of the 20 the calibration fits on
    elif setting == "switched off":
        m.fit_actor_build = False
    else:
        m.resume = True  # the earlier run's body stands
    assert bpy.ops.mocap.track() == {"FINISHED"}, m.last_error
    assert calls == [] and session.last.args["actor"] is None


@pytest.mark.bpy
def test_a_failed_fit_stops_track_with_the_reason_and_the_way_out(addon_module_name, bpy_module, monkeypatch,
                                                                   tmp_path):
    bpy, m, calls, session = _blender(addon_module_name, bpy_module, monkeypatch, tmp_path)
    errors = importlib.import_module(f"{addon_module_name}.core.actor.landmark_fit")

    def no_person(*_args, **_kwargs):
        raise errors.ProportionsFitError("no frame has 10 triangulated landmarks")

    monkeypatch.setattr(importlib.import_module(f"{addon_module_name}.operators.actor_calibration"),
                        "calibrate_actor", no_person)
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 29
    from test_addon_ui import FakeSession

    FakeSession.last = None
    with pytest.raises(RuntimeError, match="no frame has 10 triangulated landmarks.*untick Fit the Actor's Build"):
        bpy.ops.mocap.track()
    assert session.last is None and "no frame has 10 triangulated landmarks" in m.last_error  # nothing tracked


# ---- several actors: each one's build, by default too
def test_several_actors_are_each_fitted_by_default_into_their_own_folders(recorded_calibrations, tmp_path,
                                                                           monkeypatch):
    """`track --armature Lead --armature Partner` fits each actor (as one alone) into OUT/actors/<armature>/ on a
    long enough take, and hands the cast each one's fit; --no-calibrate tracks both with the rig."""
    pytest.importorskip("bpy")
    from markerless_mocap.operators import cast_session, cmd_track

    duet = scene_dir("duet")  # 60 frames
    given = []

    class Cast:
        def __init__(self, *args, actors=None, **kwargs):
            given.append(actors)
            raise cast_session.CastError("stop here")

    monkeypatch.setattr(cast_session, "CastSession", Cast)

    class Armature:
        def __init__(self, name):
            self.name = name

    monkeypatch.setattr("markerless_mocap.addon.scene_bridge.find_armature", lambda scene, name: Armature(name))
    choice = argparse.Namespace(used="numpy")
    saved = tmp_path / "earlier" / "actor.json"
    for extra in ([], ["--no-calibrate"], ["--actor", f"Lead={saved}", "--calibrate-measured", "Partner:height=1.62",
                                           "--calibrate-measured", "Partner:forearm=0.25"]):
        args = argparse.ArgumentParser()
        cmd_track.add_arguments(args)
        args = args.parse_args(["--capture", str(duet), "--out", str(tmp_path / "o"), *extra])
        assert cmd_track.run_cast(args, None, ["Lead", "Partner"], choice) == 2
    out = tmp_path / "o" / "actors"
    assert given == [[{"loaded": str(out / "Lead" / "actor.json")}, {"loaded": str(out / "Partner" / "actor.json")}],
                     [None, None], [{"loaded": str(saved)}, {"loaded": str(out / "Partner" / "actor.json")}]]
    assert recorded_calibrations == [None, None, None]  # each on the take's first 20 frames; Lead's saved one reused
    # each actor's tape measure reaches its own fit only
    assert recorded_calibrations.measured == [{}, {}, {"height": 1.62, "forearm": 0.25}]


def test_several_actors_say_whose_saved_calibration_and_measured_lengths_they_give(tmp_path):
    """With several armatures --actor and --calibrate-measured name their actor (Partner=FILE, Partner:height=1.62);
    with one the name may be left out; a value that names no armature, or two files for one actor, are refused."""
    from markerless_mocap.core.errors import InputError
    from markerless_mocap.core.actor.per_actor import options_of

    two = ["--armature", "Lead", "--armature", "Partner"]
    args = _args(tmp_path, *two, "--actor", "Partner=a=b.json", "--calibrate-measured", "Lead:height=1.7",
                 "--calibrate-measured", "Lead:forearm=0.25", "--calibrate-measured", "Partner:shin=0.4")
    assert options_of(args, "Lead") == (None, ["height=1.7", "forearm=0.25"])
    assert options_of(args, "Partner") == (Path("a=b.json"), ["shin=0.4"])
    # one armature: as before, and its own name as the prefix is understood
    assert options_of(_args(tmp_path, "--actor", "x.json"), None) == (Path("x.json"), [])
    one = _args(tmp_path, "--armature", "Lead", "--calibrate-measured", "Lead:height=1.7",
                "--calibrate-measured", "neck=0.1")
    assert options_of(one, "Lead") == (None, ["height=1.7", "neck=0.1"])
    for bad, said in ((["--calibrate-measured", "height=1.7"], "say whose it is, as in --calibrate-measured Partner:"),
                      (["--calibrate-measured", "Nobody:height=1.7"], "(armatures: Lead, Partner)"),
                      (["--actor", "x.json"], "say whose it is, as in --actor Partner="),
                      (["--actor", "Lead=x.json", "--actor", "Lead=y.json"], "2 saved calibrations for Lead")):
        with pytest.raises(InputError, match=re.escape(said)):
            options_of(_args(tmp_path, *two, *bad), "Lead")
    with pytest.raises(InputError, match="2 saved calibrations for the actor"):
        options_of(_args(tmp_path, "--actor", "x.json", "--actor", "y.json"), None)


@pytest.mark.bpy
def test_track_every_armature_in_blender_fits_each_actor_first_and_reuses_the_fits(addon_module_name, bpy_module,
                                                                                   monkeypatch, tmp_path):
    """The Track panel with Track Every Armature: each actor's build is fitted into its result folder before
    tracking, the cast gets both fits, a second Track reuses them, and with Fit the Actor's Build off it gets none."""
    from test_actor_ui import _fit

    mod = lambda name: importlib.import_module(f"{addon_module_name}.{name}")
    bpy = bpy_module
    duet = scene_dir("duet")
    bpy.ops.wm.open_mainfile(filepath=str(duet / "subject.blend"))
    calls, given = [], []

    def fake_calibrate(scene, armature, capture_dir, out_dir, settings=None, frames=None, measured=None, **_):
        calls.append((armature.name, Path(out_dir).name, list(frames), measured))
        body = mod("addon.scene_bridge").body_from_blender(armature, None, scene)
        fit = _fit(body, mod("core.actor.proportions"), mod("core.actor.landmark_fit"))
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        return fit, mod("core.actor.actor_file").save_actor(Path(out_dir) / "actor.json", fit,
                                                            subject_name=armature.name,
                                                            capture=Path(capture_dir).resolve())

    class Cast:
        def __init__(self, *args, actors=None, **kwargs):
            given.append(actors)
            raise mod("operators.cast_session").CastError("stop here")

    monkeypatch.setattr(mod("operators.actor_calibration"), "calibrate_actor", fake_calibrate)
    monkeypatch.setattr(mod("operators.cast_session"), "CastSession", Cast)
    m = bpy.context.scene.mocap
    m.every_armature = True
    m.capture_dir, m.output_dir = str(duet), str(tmp_path / "out")
    m.use_frame_range, m.frame_start, m.frame_end, m.calibrate_frames = True, 0, 29, 20
    # each actor's tape measure on its own armature, shown under its name in the Subject panel
    from test_addon_ui import _draw_all, _labels

    partner = bpy.context.scene.objects["Partner"].mocap_measured
    partner.actor_height = 2.9  # a typo: named with its actor, nothing fitted
    with pytest.raises(RuntimeError, match="Partner: Measured Height: "):
        bpy.ops.mocap.track()
    partner.actor_height = 1.62
    m.subject_checked = True
    labels = _labels(_draw_all(bpy, panels=("MOCAP_PT_subject",)))
    assert "Lead: Measured Lengths" in labels and "Partner: Measured Lengths (1 set)" in labels, labels
    for _ in range(2):
        with pytest.raises(RuntimeError, match="stop here"):
            bpy.ops.mocap.track()
    assert calls == [("Lead", "Lead", list(range(20)), {}),  # fitted once, each with its own measurements
                     ("Partner", "Partner", list(range(20)), {"height": pytest.approx(1.62)})]
    assert len(given) == 2 and all(len(a) == 2 and all(x["height_m"] > 0 for x in a) for a in given)
    assert not m.use_actor  # one actor's 'Track with Calibration' is left alone
    m.fit_actor_build = False
    with pytest.raises(RuntimeError, match="stop here"):
        bpy.ops.mocap.track()
    assert given[-1] is None
