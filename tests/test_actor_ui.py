"""Actor calibration in Blender (issue 15): the Calibrate step of the Subject panel, the copy of the rig with
the actor's proportions, and the saved calibration's round trip through the command line."""
import importlib
import subprocess
import sys

import numpy as np
import pytest

from rig_helpers import subject_blend_path

pytestmark = pytest.mark.bpy

FACTORS = {"forearm": 1.012, "thigh": 0.95}
OVERALL = 0.92


def _fit(body, proportions_mod, fit_mod):
    """A ProportionsFit of known proportions (what calibrate_actor returns), for the wiring tests."""
    p = proportions_mod.Proportions(FACTORS, OVERALL)
    actor = proportions_mod.scaled_body(body, p)
    return fit_mod.ProportionsFit(p, proportions_mod.segment_lengths(actor), proportions_mod.segment_lengths(body),
                                  [0, 1, 2], 0.02, 0.01, np.zeros((3, body.n_dof)))


@pytest.fixture
def subject_with_actor(addon_module_name, bpy_module, tmp_path):
    bpy = bpy_module
    mod = lambda name: importlib.import_module(f"{addon_module_name}.{name}")
    bpy.ops.wm.open_mainfile(filepath=str(subject_blend_path()))
    bridge = mod("addon.scene_bridge")
    arm = bridge.find_armature(bpy.context.scene)
    body = bridge.body_from_blender(arm, None, bpy.context.scene)
    fit = _fit(body, mod("core.actor.proportions"), mod("core.actor.landmark_fit"))
    path = mod("core.actor.actor_file").save_actor(tmp_path / "actor.json", fit, subject_name=arm.name)
    return bpy, mod, arm, body, fit, path


def test_calibrate_button_shows_height_and_segments(subject_with_actor, monkeypatch, tmp_path):
    bpy, mod, arm, body, fit, path = subject_with_actor
    calls = {}

    def fake_calibrate(scene, armature, capture_dir, out_dir, settings=None, frames=None, measured=None, **_):
        calls.update(armature=armature.name, frames=list(frames), out=out_dir, measured=measured)
        return fit, path

    monkeypatch.setattr(mod("operators.actor_calibration"), "calibrate_actor", fake_calibrate)
    props = bpy.context.scene.mocap
    props.capture_dir, props.output_dir = str(tmp_path), str(tmp_path / "out")
    props.use_frame_range, props.frame_start, props.frame_end, props.calibrate_frames = True, 5, 40, 12
    assert bpy.ops.mocap.calibrate_actor() == {"FINISHED"}
    assert calls["armature"] == arm.name and calls["frames"] == list(range(5, 17))
    assert calls["measured"] == {}  # no height measured: the footage's
    props.actor_height = 1.62
    assert bpy.ops.mocap.calibrate_actor() == {"FINISHED"}
    assert calls["measured"] == {"height": pytest.approx(1.62, rel=1e-6)}
    props.actor_height = 2.9  # a typo: no person is that tall
    with pytest.raises(RuntimeError, match="2.9 m is not a height of a person; give metres"):
        bpy.ops.mocap.calibrate_actor()
    props.actor_height = 1.62
    props.actor_forearm = 0.245  # a tape measure's forearm, with the height
    assert bpy.ops.mocap.calibrate_actor() == {"FINISHED"}
    assert calls["measured"] == {"height": pytest.approx(1.62, rel=1e-6), "forearm": pytest.approx(0.245, rel=1e-6)}
    props.actor_forearm = 24.5  # centimetres typed for metres: named, not clamped into a plausible length
    with pytest.raises(RuntimeError, match="Measured Forearm: 24.5 m is not a forearm of a person; give metres"):
        bpy.ops.mocap.calibrate_actor()
    props.actor_forearm = 0.245
    assert props.actor_file == str(path) and props.use_actor
    lines = props.actor_summary.splitlines()
    assert lines[0] == f"height {fit.lengths['height']:.3f} m (rig {fit.subject_lengths['height']:.3f} m)"
    assert any(line.startswith("forearm ") and "x1.012" in line for line in lines)
    # the lengths the footage reads least well say so (worth a tape measure), the others do not
    assert any(line.startswith("neck ") and line.endswith("(the footage reads it to ±5 %)") for line in lines)
    assert [line for line in lines if "the footage reads it" in line and line.startswith(("spine", "shin"))] == []
    assert any(line.startswith("upper arm ") and line.endswith("(the footage reads it to ±3 %)") for line in lines)
    # the panel shows them, with the copy button
    props.subject_checked, props.subject_dofs = True, 30
    from test_addon_ui import _draw_all

    log = _draw_all(bpy)
    labels = [e[1] for e in log if e[0] == "label"]
    assert mod("addon.panels").actor_summary_header(lines[0]) in labels
    assert ("operator", "mocap.apply_actor_copy") in log
    assert ("panel", "MOCAP_actor_summary", True) in log  # the lengths folded under the height's line
    assert ("prop", "calibrate_frames") in log and ("prop", "actor_height") in log and ("prop", "use_actor") in log
    # the measured segments, folded away, every one of the calibration's segments there; the header counts those set
    from markerless_mocap.core.actor.proportions import SEGMENTS

    assert ("panel", "MOCAP_measured_lengths", True) in log
    assert {e[1] for e in log if e[0] == "prop" and e[1].startswith("actor_")} >= {f"actor_{s}" for s in SEGMENTS}
    assert "Measured Lengths (1 set)" in labels
    # a long line (the body chosen, the masks' searches) is wrapped onto several labels, not cut off
    choice = ("took each segment halfway between the fit and the rig scaled to the fitted height: it matches the "
              "person masks best (mask mismatch rig 0.219, halfway 0.153; the landmark fit's height 1.539 m)")
    props.actor_summary += "\n" + choice
    labels = [e[1] for e in _draw_all(bpy) if e[0] == "label"]
    start = next(i for i, t in enumerate(labels) if t.startswith("took each segment"))
    assert " ".join(labels[start:]).startswith(choice) and len(labels[start]) < len(choice) / 3, labels[start:]


def test_calibrate_without_capture_names_the_fix(subject_with_actor):
    bpy = subject_with_actor[0]
    with pytest.raises(RuntimeError, match="No capture folder"):
        bpy.ops.mocap.calibrate_actor()


def test_apply_to_a_copy_scales_the_copy_and_keeps_the_rig(subject_with_actor):
    """The copy's bones and skin are the engine's scaled body, and Blender deforms the copy's skin exactly as
    the engine's FK + LBS deform the scaled body (so what the user inspects is what was tracked)."""
    bpy, mod, arm, body, fit, path = subject_with_actor
    props = bpy.context.scene.mocap
    props.actor_file = str(path)
    heads_before = np.array([b.head_local for b in arm.data.bones])
    assert bpy.ops.mocap.apply_actor_copy() == {"FINISHED"}
    copy = bpy.data.objects[arm.name + "_actor"]
    np.testing.assert_allclose(np.array([b.head_local for b in arm.data.bones]), heads_before)  # rig untouched
    actor = mod("core.actor.proportions").scaled_body(body, mod("core.actor.proportions").Proportions(FACTORS, OVERALL))
    np.testing.assert_allclose(np.array([b.head_local for b in copy.data.bones]), actor.skeleton.rest[:, :3, 3],
                               atol=2e-6)
    fore = copy.data.bones["LeftForeArm"].length / arm.data.bones["LeftForeArm"].length
    assert fore == pytest.approx(1.012, rel=1e-5)
    bridge = mod("addon.scene_bridge")
    mesh = bridge.find_skinned_mesh(copy, bpy.context.scene)
    copied = bridge.body_from_blender(copy, mesh, bpy.context.scene)
    rng = np.random.default_rng(3)
    pose = copied.default_pose()
    pose[6:] = np.clip(rng.normal(0, 0.3, copied.n_dof - 6), copied.lower[6:], copied.upper[6:])
    bridge.apply_pose(copy, copied, pose)
    blender = bridge.evaluated_world_vertices(bpy.context, mesh)
    np.testing.assert_allclose(actor.deform(pose[None])[0], blender, atol=1e-5)


def test_cli_reuses_a_saved_calibration_and_refuses_a_bad_one(subject_with_actor, tmp_path):
    bpy, mod, arm, body, fit, path = subject_with_actor
    actor_file = mod("core.actor.actor_file")
    data = actor_file.load_actor(path)
    again = actor_file.proportions_for_body(data, body)  # same rig: the saved factors exactly
    assert again.factors == fit.proportions.factors and again.overall == fit.proportions.overall
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something else"}')
    with pytest.raises(actor_file.ActorFileError, match="not an actor calibration"):
        actor_file.load_actor(bad)
    with pytest.raises(actor_file.ActorFileError, match="no actor calibration there"):
        actor_file.load_actor(tmp_path / "missing")
    edited = dict(data, overall=7.0)  # this rig's calibration with a factor no person has: the file, not the rig
    with pytest.raises(actor_file.ActorFileError, match=r"holds proportions no person has \(segment factor overall "
                                                        r"= 7.0 is outside 0.5-2.0.*; recalibrate\)$"):
        actor_file.proportions_for_body(edited, body)
    run = subprocess.run([sys.executable, "-m", "markerless_mocap", "track", "--scene", str(subject_blend_path()),
                          "--capture", str(tmp_path), "--out", str(tmp_path / "o"), "--actor", str(bad)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("markerless_mocap track: ") and "not an actor calibration" in last


@pytest.mark.slow
def test_track_calibrate_round_trip_on_the_actor_scene(tmp_path):
    """`track --calibrate` end to end (a tiny search budget, 3 calibration frames, 2 tracked): OUT/actor.json is
    written (with the mask refinement's record and the body chosen), joints.npz holds the calibrated actor's
    bones (its forearm length), and the BVH the rig's own bones (the character is keyed, not stretched)."""
    import json

    from markerless_mocap.core.actor.actor_file import load_actor

    scene = subject_blend_path().parents[1] / "actor"
    out = tmp_path / "r"
    run = subprocess.run([sys.executable, "-m", "markerless_mocap", "track", "--scene", str(scene / "subject.blend"),
                          "--capture", str(scene), "--out", str(out), "--calibrate", "--calibrate-frames", "0-2",
                          "--frames", "0-1", "--particles", "10", "--iterations", "2", "--refine", "none",
                          "--no-overlays", "--calibrate-measured", "forearm=0.245"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "actor: height" in run.stderr
    # the forearm as measured on the actor (a tape measure's 24.5 cm), not as the footage gave it
    assert "forearm 24.5 cm (rig 23.9 cm, x1.027) as measured" in run.stderr
    actor = load_actor(out / "actor.json")
    # the masks' refinement is reported for the hip width, not for the forearm the tape measure replaced
    kept = actor["silhouettes"]["kept_at_landmark_fit"]
    assert ("hip width refined against the person masks (mismatch" in run.stderr) == ("hip_width" not in kept)
    assert "forearm and hip width refined" not in run.stderr and "forearm refined" not in run.stderr
    assert actor["frames"] == [0, 1, 2] and 1.3 < actor["height_m"] < 1.8
    assert actor["measured_m"] == {"forearm": 0.245}
    assert actor["lengths_m"]["l_forearm"] == pytest.approx(0.245, rel=1e-6)
    # the landmark fit, then the masks refined the forearm and hip width (and nothing else)
    refined = actor["silhouettes"]
    assert refined["segments"] == ["forearm", "hip_width"]
    assert refined["mask_mismatch"]["refined"] <= refined["mask_mismatch"]["landmark_fit"]
    # ... then the masks chose between the rig and the fit's segments taken halfway (or, where they read the height
    # more than 3 % off the landmarks', the rig scaled to their height)
    check = refined["body_check"]
    assert len(check["height"]["grid"]) == 13
    assert list(check["mismatch"]) == ["rig", "uniform" if check["height"]["taken"] else "halfway"]
    assert check["chosen"] == min(check["mismatch"], key=check["mismatch"].get)
    fitted = check["fitted_factors"]
    changed = {k for k, v in fitted.items() if abs(v - refined["landmark_factors"][k]) > 1e-9}  # not the last bit
    assert changed <= {"forearm", "hip_width"}
    assert f"it matches the person masks best (mask mismatch rig {check['mismatch']['rig']:.3f}" in run.stderr
    # the trunk/leg split and the hip width were searched on their grids, and the summary says what they set
    assert len(check["split"]["grid"]) == 7 and len(check["hip_width"]["grid"]) == 9
    if check["chosen"] == "halfway":
        assert "spine and thigh split" in run.stderr and "hip width" in run.stderr.split("spine and thigh split")[1]
    assert json.loads((out / "report.json").read_text())["actor"]["lengths_m"] == actor["lengths_m"]
    with np.load(out / "joints.npz") as z:
        names, P = [str(n) for n in z["names"]], z["positions"]
    fore = np.linalg.norm(P[:, names.index("LeftHand")] - P[:, names.index("LeftForeArm")], axis=1)
    np.testing.assert_allclose(fore, actor["lengths_m"]["l_forearm"], rtol=1e-6)
    bvh = (out / "animation.bvh").read_text()
    for segment, child in (("l_forearm", "LeftHand"), ("l_thigh", "LeftLeg")):
        rig_length = actor["subject_lengths_m"][segment]
        offset = np.array([float(v) for v in bvh.split(f"JOINT {child}", 1)[1].split("OFFSET", 1)[1].split("\n", 1)[0]
                           .split()])
        assert np.linalg.norm(offset) == pytest.approx(rig_length, rel=1e-4)  # the character's bone in the BVH
    # ... not the actor's: the actor is 8 % shorter overall (the forearm, 10 % longer than scaled, may fit
    # the rig's length from three frames at this budget)
    assert abs(actor["subject_lengths_m"]["l_thigh"] - actor["lengths_m"]["l_thigh"]) > 0.01


def test_a_mistyped_measured_length_stops_before_anything_is_tracked(tmp_path):
    """`calibrate --measured` with an unknown segment or centimetres for metres, or `--frames` with fewer frames
    than the fit needs: exit 2 at once, one line naming the problem and the fix; `track --calibrate-measured`
    without --calibrate says what it applies to."""
    scene = subject_blend_path().parents[1] / "actor"
    base = [sys.executable, "-m", "markerless_mocap", "calibrate", "--scene", str(scene / "subject.blend"),
            "--capture", str(scene), "--out", str(tmp_path / "c")]
    for bad, says in (("tail=0.3", "SEGMENT one of height, spine, neck"), ("forearm=24.5", "give metres (0.02-1.2)"),
                      ("height=172", "172 m is not a height of a person; give metres (0.5-2.5)"),
                      ("forearm", "give SEGMENT=METRES"), ("height=tall", "'tall' is not a number")):
        run = subprocess.run(base + ["--measured", bad], capture_output=True, text=True, timeout=120)
        assert run.returncode == 2, bad
        last = run.stderr.strip().splitlines()[-1]
        assert last.startswith("markerless_mocap calibrate: --measured") and says in last, last
    assert not (tmp_path / "c").exists()
    for frames, says in (("0-1", "it was given 2 (frames 0-1) of"), ("7", "it was given 1 (frame 7) of")):
        run = subprocess.run(base + ["--frames", frames], capture_output=True, text=True, timeout=120)
        assert run.returncode == 2, frames
        last = run.stderr.strip().splitlines()[-1]
        assert "the calibration needs at least 3 frames" in last and says in last and "choose a longer range" in last
    assert not (tmp_path / "c").exists()  # refused before the session made its folder
    run = subprocess.run([sys.executable, "-m", "markerless_mocap", "track", "--scene", str(scene / "subject.blend"),
                          "--capture", str(scene), "--out", str(tmp_path / "t"), "--actor", str(tmp_path / "a.json"),
                          "--calibrate-measured", "height=1.6"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "--calibrate-measured applies to the actor calibration" in run.stderr.strip().splitlines()[-1]


def test_the_summary_says_what_the_masks_set_and_what_they_did_not():
    """The calibration summary's lines for the lengths searched against the person masks: the change where their
    best lies inside the grid, 'do not pin it down' where it lies at an end (nothing changed then)."""
    from markerless_mocap.operators.actor_calibration import _searched_by_masks

    inside = {"-0.03": 0.20, "0.0": 0.10, "0.03": 0.15}
    at_end = {"-0.03": 0.30, "0.0": 0.20, "0.03": 0.10}
    lines = _searched_by_masks({"split": {"spine_log_change": float(np.log(0.95)), "grid": inside},
                                "hip_width": {"log_change": 0.0, "grid": at_end}})
    assert lines == ["spine and thigh split by the person masks: the spine -5.0 % against the uniform scale, the "
                     "thighs making up the height", "hip width halfway: the person masks do not pin it down here"]
    lines = _searched_by_masks({"split": {"spine_log_change": 0.0, "grid": at_end},
                                "hip_width": {"log_change": float(np.log(1.042)), "grid": inside}})
    assert lines == ["spine and thigh split as the uniform scale has them: the person masks do not pin the split "
                     "down here", "hip width set by the person masks: +4.2 % against halfway"]
    assert _searched_by_masks({}) == []  # a calibration saved before these searches


def test_the_summary_says_where_the_masks_put_the_height():
    """The height line: taken (the masks and the landmarks more than 3 % apart, so the rig scaled to the masks'
    height was compared), within the gate, or not pinned down; nothing for a calibration saved before it."""
    from markerless_mocap.operators.actor_calibration import _height_by_masks

    inside = {"-0.02": 0.20, "0.0": 0.10, "0.02": 0.15}
    at_end = {"-0.02": 0.30, "0.0": 0.20, "0.02": 0.10}
    taken = {"grid": inside, "landmark_height_m": 1.667, "masks_height_m": 1.741, "taken": True}
    assert _height_by_masks({"height": taken}) == [
        "height read by the person masks: 1.741 m, the landmarks' body's (split and hip width set) 1.667 m (more "
        "than 3 % apart), so the rig scaled to it stood in for the landmarks' proportions"]
    assert _height_by_masks({"height": {**taken, "masks_height_m": 1.676, "taken": False}}) == [
        "height from the landmarks: the person masks put it at 1.676 m, within 3 %"]
    assert _height_by_masks({"height": {**taken, "grid": at_end, "taken": False}}) == [
        "height from the landmarks: the person masks do not pin it down here"]
    assert _height_by_masks({}) == []
