"""The bundled sample scenes are self-consistent: ground truth, calibration, masks, cameras, subject.

Regenerate them with `.venv/bin/python sample_scenes/generate.py` (see sample_scenes/README.md).
"""
import json
import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from markerless_mocap.core.capture.camera import BlenderCameraParams, camera_from_blender
from markerless_mocap.core.capture.calibration import read_calibration

SCENES_ROOT = Path(os.environ.get("MOCAP_SAMPLE_SCENES", Path(__file__).resolve().parents[1] / "sample_scenes"))
SCENES = ["walk", "playground", "busy", "dusk", "lobby", "actor", *(f"actor{n}" for n in range(2, 13)), "crossing",
          "crossing_alone", "duet", "crossing_dev", "crossing_dev_alone", "duet_dev", "handshake_dev", "dance", "sit",
          "long", "spin_dev", "spin", "short"]
THREE_CAMERAS = {"dance", "spin_dev", "spin", "short"}  # the hard-motion takes of issue 43 are seen by three


def scene_dir(name):
    d = SCENES_ROOT / name
    if not (d / "scene_info.json").is_file():
        pytest.skip(f"{d} not generated (run sample_scenes/generate.py)")
    return d


def load_gt(d, name="gt_joints.npz"):
    with np.load(d / name) as z:
        return [str(n) for n in z["names"]], z["frames"], z["positions"]


def actors_of(d):
    """{armature name: (gt_joints file, gt_masks folder, first-frame yaw in degrees)} of a scene: one unnamed actor
    (None) in most scenes, one per armature in a scene of several (duet)."""
    info = json.loads((d / "scene_info.json").read_text())
    if "actors" not in info:
        return {None: ("gt_joints.npz", "gt_masks", info["first_frame_yaw_deg"])}
    return {k: (a["gt_joints"], a["gt_masks"], a["first_frame_yaw_deg"]) for k, a in info["actors"].items()}


@pytest.mark.parametrize("name", SCENES)
def test_capture_folder_layout(name):
    d = scene_dir(name)
    info = json.loads((d / "scene_info.json").read_text())
    cams = read_calibration(d)
    assert [c.name for c in cams] == info["cameras"]
    assert (3 if name in THREE_CAMERAS else 4) <= len(cams) <= 5
    names, frames, P = load_gt(d)
    assert len(names) == 31 and P.shape == (len(frames), 31, 3)
    longest = 600 if name == "long" else 120                  # long: issue 44's take for chunked tracking
    assert 40 <= len(frames) <= longest and np.array_equal(frames, np.arange(len(frames)))
    assert np.all(np.isfinite(P))
    # feet on the floor: the lowest joint is within a few cm of z = 0 in most frames
    assert abs(np.median(P[..., 2].min(axis=1))) < 0.12
    if (d / "videos").is_dir():
        for c in cams:
            cap = cv2.VideoCapture(str(d / "videos" / f"{c.name}.mp4"))
            assert cap.isOpened(), c.name
            assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(frames)
            assert (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))) == c.size
            cap.release()
    if name == "walk":
        for c in cams:
            plate = cv2.imread(str(d / "background" / f"{c.name}.png"))
            assert plate is not None and plate.shape == (c.height, c.width, 3)


@pytest.mark.parametrize("name", SCENES)
def test_ground_truth_joints_land_inside_the_silhouettes(name):
    d = scene_dir(name)
    cams = read_calibration(d)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))    # 2-pixel dilation
    for gt_file, masks, _ in actors_of(d).values():  # each actor's joints in its own masks
        names, frames, P = load_gt(d, gt_file)
        hits = total = 0
        for c in cams:
            mask_files = sorted((d / masks / c.name).glob("*.png"))
            assert len(mask_files) >= 5, c.name
            for mf in mask_files:
                f = int(mf.stem)
                mask = cv2.imread(str(mf), cv2.IMREAD_GRAYSCALE)
                assert mask.shape == (c.height, c.width)
                assert 0.002 < np.count_nonzero(mask) / mask.size < 0.3    # a person, not empty or full
                grown = cv2.dilate(mask, kernel) > 0
                uv = np.rint(c.project(P[f])).astype(int)
                ok = (uv[:, 0] >= 0) & (uv[:, 0] < c.width) & (uv[:, 1] >= 0) & (uv[:, 1] < c.height)
                inside = np.zeros(len(uv), bool)
                inside[ok] = grown[uv[ok, 1], uv[ok, 0]]
                hits += int(inside.sum())
                total += len(uv)
        assert total >= 31 * 5 * len(cams)
        assert hits / total >= 0.99, f"{gt_file}: {hits}/{total} joint projections inside {masks}"


@pytest.mark.parametrize("name", SCENES)
def test_joints_miss_shifted_masks(name):
    """Negative control: the same check with the masks moved by 25 px fails clearly."""
    d = scene_dir(name)
    cams = read_calibration(d)
    _, _, P = load_gt(d)
    hits = total = 0
    for c in cams:
        for mf in sorted((d / "gt_masks" / c.name).glob("*.png")):
            mask = np.roll(cv2.imread(str(mf), cv2.IMREAD_GRAYSCALE), 25, axis=1) > 0
            uv = np.rint(c.project(P[int(mf.stem)])).astype(int)
            uv = np.clip(uv, 0, [c.width - 1, c.height - 1])
            hits += int(mask[uv[:, 1], uv[:, 0]].sum())
            total += len(uv)
    assert hits / total < 0.9


@pytest.mark.parametrize("name", SCENES)
def test_calibration_reproduces_the_render_cameras(name):
    d = scene_dir(name)
    rec = json.loads((d / "render_cameras.json").read_text())["cameras"]
    cams = {c.name: c for c in read_calibration(d)}
    assert sorted(cams) == sorted(r["name"] for r in rec)
    for r in rec:
        assert r["resolution_percentage"] == 100
        params = BlenderCameraParams(np.array(r["matrix_world"]), r["lens"], r["sensor_width"], r["sensor_height"],
                                     r["sensor_fit"], r["shift_x"], r["shift_y"], r["resolution_x"],
                                     r["resolution_y"], r["pixel_aspect_x"], r["pixel_aspect_y"], r["name"])
        rendered = camera_from_blender(params)
        cal = cams[r["name"]]
        # Blender stores lens/shift as float32: compare K relative to the focal length
        np.testing.assert_allclose(rendered.K, cal.K, rtol=0, atol=1e-6 * cal.K[0, 0])
        np.testing.assert_allclose(rendered.R, cal.R, atol=1e-6)
        np.testing.assert_allclose(rendered.t, cal.t, atol=1e-6)
        assert cal.size == (r["resolution_x"], r["resolution_y"])
        assert np.all(cal.dist == 0)
        assert 1.2 <= cal.center[2] <= 2.5  # tripods; actor6 mounted high (2.1-2.4 m)


@pytest.mark.bpy
@pytest.mark.parametrize("name", SCENES)
def test_subject_blend_is_a_rest_pose_rig_near_the_start(name, bpy_module):
    bpy = bpy_module
    d = scene_dir(name)
    bpy.ops.wm.open_mainfile(filepath=str(d / "subject.blend"))
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    actors = actors_of(d)
    assert len(arms) == len(meshes) == len(actors)
    if len(actors) > 1:  # a scene of several actors: each armature named after its actor (its truth's file name)
        assert sorted(o.name for o in arms) == sorted(actors)
    for arm in arms:
        body = next(o for o in meshes if o.parent == arm)
        assert len(arm.data.bones) == 31
        assert any(m.type == "ARMATURE" and m.object == arm for m in body.modifiers)
        tris = sum(len(p.vertices) - 2 for p in body.data.polygons)
        assert 5000 <= tris <= 6000
        assert {g.name for g in body.vertex_groups} == {b.name for b in arm.data.bones}
        sums = np.array([sum(g.weight for g in v.groups) for v in body.data.vertices])
        np.testing.assert_allclose(sums, 1.0, atol=1e-4)
        assert arm.animation_data is None or arm.animation_data.action is None
        for pb in arm.pose.bones:
            np.testing.assert_allclose(np.array(pb.matrix_basis), np.eye(4), atol=1e-9)
        # placed where its person starts, with a small honest error (architecture: 20 cm, 30 degrees)
        gt_file, _, first_yaw = actors[arm.name if len(actors) > 1 else None]
        names, _, P = load_gt(d, gt_file)
        M = np.array(arm.matrix_world)
        hips = M[:3, :3] @ np.array(arm.data.bones["Hips"].head_local) + M[:3, 3]
        err = np.linalg.norm(hips[:2] - P[0, names.index("Hips"), :2])
        assert 0.03 < err < 0.20
        yaw = math.degrees(math.atan2(M[1, 0], M[0, 0]))
        dyaw = (yaw - first_yaw + 180) % 360 - 180
        assert 5 < abs(dyaw) < 30


# ---- busy: the hard scene of issue 13 (measured on, not tuned on) ---------------------------------
def _body_frame(names, P):
    idx = {n: k for k, n in enumerate(names)}
    up = P[:, idx["Neck"]] - P[:, idx["Hips"]]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    lat = P[:, idx["LeftArm"]] - P[:, idx["RightArm"]]
    lat -= (lat * up).sum(axis=1, keepdims=True) * up
    lat /= np.linalg.norm(lat, axis=1, keepdims=True)
    return idx, up, lat, np.cross(lat, up)


def test_busy_hands_reach_the_face_and_cross_the_torso():
    d = scene_dir("busy")
    names, _, P = load_gt(d)
    idx, up, lat, fwd = _body_frame(names, P)
    at_face = crossing = 0
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        h = P[:, idx[f"{side}Hand"]]
        at_face += int((np.linalg.norm(h - P[:, idx["Head"]], axis=1) < 0.15).sum())
        rel = h - P[:, idx["Hips"]]
        crossing += int(((sign * (rel * lat).sum(axis=1) < 0) & ((rel * fwd).sum(axis=1) > 0.05)).sum())
    assert at_face >= 8 and crossing >= 20, (at_face, crossing)
    # fast limbs: a wrist moves faster than 4 m/s somewhere, but nothing jumps (under 10 m/s)
    speed = np.linalg.norm(np.diff(P[:, [idx["LeftHand"], idx["RightHand"]]], axis=0), axis=2) * 30
    assert 4.0 < speed.max() < 10.0


def test_busy_second_person_is_seen_in_every_view():
    d = scene_dir("busy")
    info = json.loads((d / "scene_info.json").read_text())
    views = info["second_person"]["views"]
    assert sorted(views) == sorted(info["cameras"])
    for name, v in views.items():
        assert v["in_view_fraction"] >= 0.9, name
    assert sum(v["behind_subject_frames"] for v in views.values()) > 0


def assert_light_changes_several_fold(video):
    """The frame's mean grey level changes more than twofold over the clip, and its blue/red balance by
    more than 0.15 (warm to cool light)."""
    cap = cv2.VideoCapture(str(video))
    grey, blue_red = [], []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        m = img.reshape(-1, 3).mean(axis=0)
        grey.append(m.mean())
        blue_red.append(m[0] / m[2])
    cap.release()
    assert max(grey) / min(grey) > 2.0
    assert max(blue_red) - min(blue_red) > 0.15


def test_busy_light_changes_several_fold():
    d = scene_dir("busy")
    if not (d / "videos").is_dir():
        pytest.skip("busy rendered without videos")
    assert_light_changes_several_fold(d / "videos" / "cam1.mp4")


# ---- dusk: held out (issue 13), for judging whether changes generalise; never tuned on ----------------
def test_dusk_hands_go_overhead_to_the_face_and_to_the_other_shoulder():
    d = scene_dir("dusk")
    names, _, P = load_gt(d)
    idx = {n: k for k, n in enumerate(names)}
    head = P[:, idx["Head"]]
    at_face = sum(int((np.linalg.norm(P[:, idx[f"{s}Hand"]] - head, axis=1) < 0.15).sum()) for s in ("Left", "Right"))
    overhead = int((P[:, idx["RightHand"], 2] > head[:, 2] + 0.15).sum())
    on_shoulder = sum(int((np.linalg.norm(P[:, idx[f"{s}Hand"]] - P[:, idx[f"{o}Arm"]], axis=1) < 0.12).sum())
                      for s, o in (("Left", "Right"), ("Right", "Left")))
    assert at_face >= 8 and overhead >= 6 and on_shoulder >= 8, (at_face, overhead, on_shoulder)
    speed = np.linalg.norm(np.diff(P[:, [idx["LeftHand"], idx["RightHand"]]], axis=0), axis=2) * 30
    assert 4.0 < speed.max() < 10.0
    # it turns round and jumps: the hips leave the floor height of the standing frames
    assert P[:, idx["Hips"], 2].max() - np.median(P[:, idx["Hips"], 2]) > 0.15


def assert_second_person_in_every_view_and_changing_light(name, camera):
    d = scene_dir(name)
    info = json.loads((d / "scene_info.json").read_text())
    views = info["second_person"]["views"]
    assert sorted(views) == sorted(info["cameras"])
    assert all(v["in_view_fraction"] >= 0.9 for v in views.values())
    if not (d / "videos").is_dir():
        pytest.skip(f"{name} rendered without videos")
    assert_light_changes_several_fold(d / "videos" / f"{camera}.mp4")


def test_dusk_second_person_and_changing_light():
    assert_second_person_in_every_view_and_changing_light("dusk", "cam2")


def _frames_at_face(P, idx, hand):
    """How many frames of the joints P (T,J,3) have `hand` within 15 cm of the head."""
    return int((np.linalg.norm(P[:, idx[hand]] - P[:, idx["Head"]], axis=1) < 0.15).sum())


def _frames_overhead(P, idx, hand):
    """How many frames have `hand` more than 10 cm above the head."""
    return int((P[:, idx[hand], 2] > P[:, idx["Head"], 2] + 0.1).sum())


def _both_arms_crossed(P, idx, lat, fwd):
    """Per frame: both hands across the body's midline and in front of the hips."""
    crossed = np.ones(len(P), bool)
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        rel = P[:, idx[f"{side}Hand"]] - P[:, idx["Hips"]]
        crossed &= (sign * (rel * lat).sum(axis=1) < 0) & ((rel * fwd).sum(axis=1) > 0.05)
    return crossed


# ---- lobby: held out like dusk, made before anything was measured on it -------------------------------
def test_lobby_arms_cross_both_ways_and_the_body_jumps():
    d = scene_dir("lobby")
    names, _, P = load_gt(d)
    idx, up, lat, fwd = _body_frame(names, P)
    both_crossed = _both_arms_crossed(P, idx, lat, fwd)
    at_face = _frames_at_face(P, idx, "LeftHand")
    overhead = _frames_overhead(P, idx, "LeftHand")
    assert both_crossed.sum() >= 8 and at_face >= 4 and overhead >= 2, (both_crossed.sum(), at_face, overhead)
    assert P[:, idx["Hips"], 2].max() - np.median(P[:, idx["Hips"], 2]) > 0.1  # forward jumps


def test_lobby_second_person_and_changing_light():
    assert_second_person_in_every_view_and_changing_light("lobby", "cam3")


# ---- actor: a body of other proportions than the subject the tracker is given (issue 15) ------------
def test_actor_is_shorter_with_longer_forearms_than_its_subject():
    """The ground truth is the actor's: 8 % shorter than walk's subject, forearms 10 % longer than that; the
    subject.blend is walk's, unchanged."""
    d = scene_dir("actor")
    info = json.loads((d / "scene_info.json").read_text())["actor"]
    true, subject = info["true_segment_lengths_m"], info["subject_segment_lengths_m"]
    assert true["height"] / subject["height"] == pytest.approx(0.92, abs=0.005)
    assert true["forearm"] / subject["forearm"] == pytest.approx(0.92 * 1.10, rel=1e-6)
    for seg in ("spine", "upper_arm", "thigh", "shin"):
        assert true[seg] / subject[seg] == pytest.approx(0.92, rel=1e-6), seg
    names, _, P = load_gt(d)
    fore = np.linalg.norm(P[:, names.index("LeftHand")] - P[:, names.index("LeftForeArm")], axis=1)
    np.testing.assert_allclose(fore, true["l_forearm"], atol=1e-4)  # the rendered bones are the actor's
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "walk" / "subject.blend").read_bytes()


def _assert_built(ratio, overall, relatives):
    """Each (segment, relative) of `relatives`: the actor's segment is `overall` x `relative` the subject's."""
    for seg, relative in relatives:
        assert ratio[seg] == pytest.approx(overall * relative, rel=1e-6), seg


def _actor_lengths(d):
    """The rendered actor's true segment lengths (m) and their ratios to the tracker's subject's."""
    info = json.loads((d / "scene_info.json").read_text())["actor"]
    true, subject = info["true_segment_lengths_m"], info["subject_segment_lengths_m"]
    return true, {seg: true[seg] / subject[seg] for seg in true}


def test_actor2_is_built_otherwise_than_a_scaled_subject():
    """The held-out actor: 5 % taller than walk's subject, and relative to that wider shoulders and hips, a
    longer spine, shorter thighs and forearms; the rendered bones are that actor's."""
    d = scene_dir("actor2")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.05, (("spine", 1.04), ("thigh", 0.95), ("forearm", 0.94), ("upper_arm", 1.0), ("shin", 1.0)))
    assert ratio["shoulder_width"] > 1.05 * 1.06 and ratio["hip_width"] > 1.05 * 1.04  # widths: joint to joint
    names, _, P = load_gt(d)
    thigh = np.linalg.norm(P[:, names.index("LeftLeg")] - P[:, names.index("LeftUpLeg")], axis=1)
    np.testing.assert_allclose(thigh, true["l_thigh"], atol=1e-4)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "walk" / "subject.blend").read_bytes()


def test_actor3_is_slight_and_long_limbed():
    """The second held-out actor: 3 % shorter than playground's subject, a longer neck, narrower shoulders and
    hips, a shorter spine, longer thighs, shins and upper arms; the rendered bones are that actor's."""
    d = scene_dir("actor3")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 0.97, (("neck", 1.12), ("spine", 0.96), ("thigh", 1.05), ("shin", 1.04), ("upper_arm", 1.04),
                                ("forearm", 1.0)))
    assert ratio["shoulder_width"] < 0.97 * 0.95 and ratio["hip_width"] < 0.97 * 0.97  # widths: joint to joint
    names, _, P = load_gt(d)
    shin = np.linalg.norm(P[:, names.index("LeftFoot")] - P[:, names.index("LeftLeg")], axis=1)
    np.testing.assert_allclose(shin, true["l_shin"], atol=1e-4)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()


def test_actor4_is_stocky_with_a_long_trunk_on_short_legs():
    """The third held-out actor, the opposite of actor3: 5 % shorter than playground's subject, a longer spine
    on shorter thighs and shins, a shorter neck, wider shoulders and hips, filmed by five cameras."""
    d = scene_dir("actor4")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 0.95, (("spine", 1.06), ("neck", 0.92), ("thigh", 0.94), ("shin", 0.96), ("upper_arm", 0.97),
                                ("forearm", 1.04)))
    assert ratio["shoulder_width"] > 0.95 * 1.04 and ratio["hip_width"] > 0.95 * 1.01  # widths: joint to joint
    names, _, P = load_gt(d)
    thigh = np.linalg.norm(P[:, names.index("RightLeg")] - P[:, names.index("RightUpLeg")], axis=1)
    np.testing.assert_allclose(thigh, true["r_thigh"], atol=1e-4)
    assert len(json.loads((d / "render_cameras.json").read_text())["cameras"]) == 5
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()



def test_actor5_is_tall_and_long_armed():
    """The fourth held-out actor: 7 % taller than playground's subject, longer arms and legs, narrower hips, a
    slightly shorter spine, filmed from further out than the other scenes, jumping forwards."""
    d = scene_dir("actor5")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.07, (("upper_arm", 1.05), ("forearm", 1.06), ("spine", 0.98), ("thigh", 1.03),
                                ("shin", 1.02), ("neck", 1.0)))
    assert ratio["hip_width"] < 1.07 * 0.96  # widths: joint to joint
    names, _, P = load_gt(d)
    fore = np.linalg.norm(P[:, names.index("RightHand")] - P[:, names.index("RightForeArm")], axis=1)
    np.testing.assert_allclose(fore, true["r_forearm"], atol=1e-4)
    hips = np.array(json.loads((d / "scene_info.json").read_text())["first_frame_hips"])
    cameras = json.loads((d / "render_cameras.json").read_text())["cameras"]
    distances = [np.hypot(*(np.array(c["matrix_world"])[:2, 3] - hips[:2])) for c in cameras]
    assert len(cameras) == 4 and np.mean(distances) > 4.0
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()


def test_actor6_has_the_subjects_height_and_other_proportions():
    """The fifth held-out actor: the subject's height within 1 %, but wider hips, narrower shoulders, shorter
    arms, a longer neck and shins; filmed by cameras mounted high, crouching deeply."""
    d = scene_dir("actor6")
    true, ratio = _actor_lengths(d)
    assert ratio["height"] == pytest.approx(1.0, abs=0.01)
    _assert_built(ratio, 0.98, (("upper_arm", 0.95), ("forearm", 0.96), ("spine", 1.03), ("neck", 1.05), ("shin", 1.03),
                                ("foot", 1.04), ("thigh", 1.0)))
    assert ratio["hip_width"] > 0.98 * 1.04 and ratio["shoulder_width"] < 0.98 * 0.97  # widths: joint to joint
    names, _, P = load_gt(d)
    assert P[:, names.index("Hips"), 2].max() - P[:, names.index("Hips"), 2].min() > 0.15  # the crouch
    cameras = json.loads((d / "render_cameras.json").read_text())["cameras"]
    assert len(cameras) == 4 and min(np.array(c["matrix_world"])[2][3] for c in cameras) > 2.0
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()


def test_actor7_has_a_short_trunk_on_long_legs():
    """The sixth held-out actor: 2 % taller than playground's subject, a shorter spine and neck on longer thighs
    and shins, wider shoulders; standing."""
    d = scene_dir("actor7")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.02, (("spine", 0.95), ("neck", 0.95), ("thigh", 1.05), ("shin", 1.03), ("forearm", 1.0)))
    assert ratio["shoulder_width"] > 1.02 * 1.02
    names, _, P = load_gt(d)
    spine = np.linalg.norm(P[:, names.index("Neck")] - P[:, names.index("Hips")], axis=1)
    thigh = np.linalg.norm(P[:, names.index("LeftLeg")] - P[:, names.index("LeftUpLeg")], axis=1)
    np.testing.assert_allclose(thigh, true["l_thigh"], atol=1e-4)
    assert np.all(spine < true["spine"] + 1e-3)  # the trunk's bones bend, never lengthen
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()

def test_actor8_has_long_forearms_on_a_smaller_body():
    """The seventh held-out actor: 6 % shorter than playground's subject, forearms 9 % longer than that, upper
    arms shorter, hips narrower, shins longer; the rendered forearms are that actor's."""
    d = scene_dir("actor8")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 0.94, (("forearm", 1.09), ("upper_arm", 0.96), ("shin", 1.03), ("spine", 1.0), ("thigh", 1.0)))
    assert ratio["hip_width"] < 0.94 * 0.98  # widths: joint to joint
    names, _, P = load_gt(d)
    forearm = np.linalg.norm(P[:, names.index("LeftHand")] - P[:, names.index("LeftForeArm")], axis=1)
    np.testing.assert_allclose(forearm, true["l_forearm"], atol=1e-4)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()


def test_actor9_is_a_build_of_its_own_in_an_uncontrolled_room():
    """The eighth held-out actor, the first in users' conditions: 4 % taller than playground's subject, longer
    upper arms on shorter forearms, narrower shoulders, a longer neck, shorter thighs on longer shins, shorter
    feet; no plates, a second person and light changing several-fold; a hand at the face and one overhead."""
    d = scene_dir("actor9")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.04, (("upper_arm", 1.06), ("forearm", 0.95), ("neck", 1.06), ("thigh", 0.96), ("shin", 1.03),
                                ("foot", 0.95), ("spine", 1.0)))
    assert ratio["shoulder_width"] < 1.04 * 0.97  # widths: joint to joint
    assert not (d / "background").exists()
    names, _, P = load_gt(d)
    idx = {n: k for k, n in enumerate(names)}
    at_face = _frames_at_face(P, idx, "RightHand")
    overhead = _frames_overhead(P, idx, "RightHand")
    assert at_face >= 4 and overhead >= 4, (at_face, overhead)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()
    assert_second_person_in_every_view_and_changing_light("actor9", "cam1")


def test_actor10_is_a_studio_build_with_wide_shoulders_and_long_feet():
    """The ninth held-out actor: 4 % shorter than playground's subject, shoulders wider, upper arms longer and
    forearms shorter, a shorter spine, longer thighs and feet; plates."""
    d = scene_dir("actor10")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 0.96, (("upper_arm", 1.04), ("forearm", 0.96), ("spine", 0.97), ("thigh", 1.03),
                                ("foot", 1.06), ("shin", 1.0), ("neck", 1.0)))
    assert ratio["shoulder_width"] > 0.96 * 1.04
    names, _, P = load_gt(d)
    forearm = np.linalg.norm(P[:, names.index("RightHand")] - P[:, names.index("RightForeArm")], axis=1)
    np.testing.assert_allclose(forearm, true["r_forearm"], atol=1e-4)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "playground" / "subject.blend").read_bytes()


def test_actor11_is_a_long_trunk_on_short_thighs_in_an_uncontrolled_room():
    """The tenth held-out actor, the second in an uncontrolled room: 3 % shorter than the subject, a longer spine
    on shorter thighs, wider hips and shoulders, a shorter neck, longer forearms; a hand at the face, the other
    overhead; lobby's subject.blend (facing the way this clip does), a second person, changing light."""
    d = scene_dir("actor11")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 0.97, (("spine", 1.05), ("thigh", 0.95), ("neck", 0.95), ("forearm", 1.04), ("upper_arm", 1.0),
                                ("shin", 1.0), ("foot", 1.0)))
    assert ratio["hip_width"] > 0.97 * 1.04 and ratio["shoulder_width"] > 0.97 * 1.01  # widths: joint to joint
    assert not (d / "background").exists()
    names, _, P = load_gt(d)
    idx = {n: k for k, n in enumerate(names)}
    at_face = _frames_at_face(P, idx, "LeftHand")
    overhead = _frames_overhead(P, idx, "RightHand")
    assert at_face >= 4 and overhead >= 4, (at_face, overhead)
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "lobby" / "subject.blend").read_bytes()
    assert_second_person_in_every_view_and_changing_light("actor11", "cam1")


def test_actor12_is_tall_with_narrow_hips_in_an_uncontrolled_room():
    """The eleventh held-out actor, the third in an uncontrolled room: 6 % taller than the subject, narrower hips,
    wider shoulders, shorter upper arms, longer shins and feet, a slightly shorter spine; both arms crossed, then
    a hand on the other shoulder, while jumping; lobby's subject.blend, a second person, changing light."""
    d = scene_dir("actor12")
    true, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.06, (("upper_arm", 0.97), ("shin", 1.04), ("foot", 1.04), ("spine", 0.98), ("forearm", 1.0),
                                ("thigh", 1.0), ("neck", 1.0)))
    assert ratio["hip_width"] < 1.06 * 0.97 and ratio["shoulder_width"] > 1.06 * 1.02
    names, _, P = load_gt(d)
    idx, up, lat, fwd = _body_frame(names, P)
    both_crossed = _both_arms_crossed(P, idx, lat, fwd)
    on_shoulder = int((np.linalg.norm(P[:, idx["LeftHand"]] - P[:, idx["RightArm"]], axis=1) < 0.15).sum())
    assert both_crossed.sum() >= 6 and on_shoulder >= 4, (both_crossed.sum(), on_shoulder)
    assert np.ptp(P[:, idx["Hips"], 2]) > 0.3  # jumps
    assert (d / "subject.blend").read_bytes() == (SCENES_ROOT / "lobby" / "subject.blend").read_bytes()
    assert_second_person_in_every_view_and_changing_light("actor12", "cam1")


# ---- crossing: issue 42's other person, rendered before any tuning (held out) -------------------------------
def test_crossing_second_person_passes_in_front_close_by_and_stops_beside():
    """A second person dressed like the subject walks between it and cam1, then cam2 (hiding over a fifth of its
    silhouette there in several frames, nothing at the first frame), the bodies within 0.3 m (nearest joints), and
    slows to a stop beside it; its joints are in second_person_joints.npz."""
    d = scene_dir("crossing")
    info = json.loads((d / "scene_info.json").read_text())
    other = info["second_person"]
    assert 0.1 < other["closest_joints_m"] <= 0.3 and other["closest_hips_m"] <= 0.5
    assert 0.5 < other["last_frame_hips_m"] < 0.9 and other["last_frame_speed_m_per_s"] < 0.3
    hidden = other["hidden_by_second_person"]
    assert sorted(hidden) == sorted(info["cameras"])
    assert hidden["cam1"]["frames_hidden_over_20_percent"] >= 5 and hidden["cam2"]["frames_hidden_over_20_percent"] >= 5
    assert all(v["hidden_fraction"][0] == 0 for v in hidden.values())  # the subject is placed on an actor in plain view
    for part in ("shirt", "trousers"):  # dressed like the subject
        assert np.abs(np.subtract(other["clothing_colours_linear_rgb"][part],
                                  info["clothing_colours_linear_rgb"][part])).max() < 0.02
    names, frames, P = load_gt(d)
    with np.load(d / "second_person_joints.npz") as z:
        assert [str(n) for n in z["names"]] == names and np.array_equal(z["frames"], frames)
        hips = np.linalg.norm(z["positions"][:, 0, :2] - P[:, 0, :2], axis=1)
    assert hips.min() == pytest.approx(other["closest_hips_m"], abs=1e-6)


@pytest.mark.parametrize("name", ["crossing", "crossing_dev"])
def test_crossing_alone_is_the_same_capture_without_the_second_person(name):
    """For the issue's "within 3 mm of the same motion rendered without the second person": the same truth,
    cameras, subject.blend and room, and a picture that differs only where the second person is."""
    a, b = scene_dir(name), scene_dir(f"{name}_alone")
    assert "second_person" not in json.loads((b / "scene_info.json").read_text())
    assert not (b / "second_person_joints.npz").exists()
    np.testing.assert_array_equal(load_gt(a)[2], load_gt(b)[2])
    for name in ("calibration.toml", "subject.blend"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    for c in read_calibration(a):
        plate_a, plate_b = (cv2.imread(str(d / "background" / f"{c.name}.png")).astype(int) for d in (a, b))
        assert np.abs(plate_a - plate_b).mean() < 1.0, c.name  # both empty rooms
    if not (a / "videos").is_dir() or not (b / "videos").is_dir():
        pytest.skip("crossing rendered without videos")
    info = json.loads((a / "scene_info.json").read_text())
    frame = int(np.argmax(info["second_person"]["hidden_by_second_person"]["cam1"]["hidden_fraction"]))
    pictures = []
    for d in (a, b):
        cap = cv2.VideoCapture(str(d / "videos" / "cam1.mp4"))
        cap.set(cv2.CAP_PROP_POS_FRAMES, frame)
        ok, img = cap.read()
        cap.release()
        assert ok
        pictures.append(img.astype(int))
    changed = np.abs(pictures[0] - pictures[1]).max(axis=2) > 40
    assert 0.01 < changed.mean() < 0.2  # a person's worth of the picture, not the whole


# ---- crossing_dev: issue 42's DEVELOPMENT scene (tuned on; the held-out crossing judges) --------------------------
def test_crossing_dev_second_person_hides_the_actor_in_two_views_and_stops_beside():
    """The crossing idea on other material: a second person dressed like the actor passes within 0.3 m (joints),
    0.4-0.5 m (hips), hides half to four fifths of the actor in cam1 and cam2 for several frames (nothing at the
    first frame, little in the other views) and stops beside it (60-120 degrees off its last facing)."""
    d = scene_dir("crossing_dev")
    info = json.loads((d / "scene_info.json").read_text())
    other = info["second_person"]
    assert 0.05 < other["closest_joints_m"] < 0.3 and 0.4 <= other["closest_hips_m"] <= 0.5
    assert 0.6 < other["last_frame_hips_m"] < 0.9 and other["last_frame_speed_m_per_s"] < 0.1
    hidden = other["hidden_by_second_person"]
    assert sorted(hidden) == sorted(info["cameras"])
    for cam in ("cam1", "cam2"):
        assert 0.5 <= hidden[cam]["max_hidden"] <= 0.8 and hidden[cam]["frames_hidden_over_20_percent"] >= 8, cam
    assert all(hidden[cam]["max_hidden"] < 0.2 for cam in hidden if cam not in ("cam1", "cam2"))
    assert all(v["hidden_fraction"][0] == 0 for v in hidden.values())
    for part in ("shirt", "trousers"):
        assert np.abs(np.subtract(other["clothing_colours_linear_rgb"][part],
                                  info["clothing_colours_linear_rgb"][part])).max() < 0.02
    names, frames, P = load_gt(d)
    with np.load(d / "second_person_joints.npz") as z:
        assert [str(n) for n in z["names"]] == names and np.array_equal(z["frames"], frames)
        P2 = z["positions"]
    assert np.linalg.norm(P2[:, 0, :2] - P[:, 0, :2], axis=1).min() == pytest.approx(other["closest_hips_m"], abs=1e-6)
    fwd = _body_frame(names, P)[3][-1, :2]
    to_other = P2[-1, 0, :2] - P[-1, 0, :2]
    off = math.degrees(math.acos(np.dot(to_other, fwd) / np.linalg.norm(to_other) / np.linalg.norm(fwd)))
    assert 60 < off < 120


def test_crossing_dev_is_other_material_than_the_held_out_crossing():
    """Tuned on, so it shares nothing with crossing but the idea: other clip windows (no actor frame in common),
    seed, cameras and clothes."""
    dev, held = (json.loads((scene_dir(n) / "scene_info.json").read_text()) for n in ("crossing_dev", "crossing"))
    first, last = dev["first_source_frame_30fps"], dev["first_source_frame_30fps"] + dev["n_frames"] - 1
    assert last < held["first_source_frame_30fps"] or first > held["first_source_frame_30fps"] + held["n_frames"] - 1
    assert dev["second_person"]["source"] != held["second_person"]["source"]
    assert dev["clothing_colours_linear_rgb"] != held["clothing_colours_linear_rgb"]
    dev_cams, held_cams = (read_calibration(scene_dir(n)) for n in ("crossing_dev", "crossing"))
    assert all(np.linalg.norm(a.center - b.center) > 0.5 for a, b in zip(dev_cams, held_cams))
    assert (scene_dir("crossing_dev") / "subject.blend").read_bytes() != \
        (scene_dir("crossing") / "subject.blend").read_bytes()


# ---- duet: issue 42's several actors, two tracked people, rendered before any tuning (held out) ----------------
def test_duet_has_two_actors_of_other_builds_each_with_its_truth():
    """Lead (actor2's build) and Partner (actor3's), in clothes of their own, each with its truth in gt_joints.npz's
    format (the Lead's is gt_joints.npz too), its masks and its armature placed on it at the first frame."""
    d = scene_dir("duet")
    info = json.loads((d / "scene_info.json").read_text())
    actors = info["actors"]
    assert list(actors) == ["Lead", "Partner"]
    names, frames, P = load_gt(d)
    with np.load(d / "gt_joints.npz") as z:
        keys = sorted(z.files)
    truth = {}
    for who in actors:
        with np.load(d / f"gt_joints_{who}.npz") as z:
            assert sorted(z.files) == keys and float(z["fps"]) == 30.0
            assert [str(n) for n in z["names"]] == names and np.array_equal(z["frames"], frames)
            truth[who] = z["positions"]
        assert (d / f"gt_masks_{who}" if who != "Lead" else d / "gt_masks").is_dir()
        placement = actors[who]["subject_placement"]
        assert placement["offset_norm_m"] == pytest.approx(0.1) and abs(placement["yaw_error_deg"]) == pytest.approx(15)
    np.testing.assert_array_equal(truth["Lead"], P)
    standard = info["actor"]["subject_segment_lengths_m"]
    lead, partner = (actors[w]["true_segment_lengths_m"] for w in ("Lead", "Partner"))
    assert actors["Lead"]["proportions_from"] == "actor2" and actors["Partner"]["proportions_from"] == "actor3"
    ratio = {who: {k: v / standard[k] for k, v in actors[who]["true_segment_lengths_m"].items()} for who in actors}
    _assert_built(ratio["Lead"], 1.05, (("spine", 1.04), ("thigh", 0.95), ("forearm", 0.94)))
    _assert_built(ratio["Partner"], 0.97, (("neck", 1.12), ("thigh", 1.05), ("shin", 1.04)))
    assert lead["height"] - partner["height"] > 0.08 and lead["shoulder_width"] / partner["shoulder_width"] > 1.15
    for who, lengths in (("Lead", lead), ("Partner", partner)):  # the rendered bones are that actor's
        thigh = np.linalg.norm(truth[who][:, names.index("LeftLeg")] - truth[who][:, names.index("LeftUpLeg")], axis=1)
        np.testing.assert_allclose(thigh, lengths["l_thigh"], atol=1e-4)
    shirts = [actors[w]["clothing_colours_linear_rgb"]["shirt"] for w in actors]
    assert np.abs(np.subtract(*shirts)).max() > 0.1


def test_duet_actors_hide_each_other_in_two_views_each_then_shake_hands():
    """Each hides over a fifth of the other in two views (never at the first frame); the Partner passes within 0.7 m
    of the Lead without touching, stops 0.8-1.0 m from it facing it, and both right wrists meet midway, a clasp
    apart, at waist to chest height, over the last frames."""
    d = scene_dir("duet")
    info = json.loads((d / "scene_info.json").read_text())
    for key in ("Lead_hidden_by_Partner", "Partner_hidden_by_Lead"):
        hidden = info["hidden"][key]
        assert sorted(hidden) == sorted(info["cameras"])
        assert sum(v["frames_hidden_over_20_percent"] >= 10 for v in hidden.values()) >= 2, key
        assert all(v["hidden_fraction"][0] == 0 for v in hidden.values()), key
    partner, hs = info["partner"], info["handshake"]
    assert partner["closest_hips_m"] < 0.7 and partner["closest_joints_before_handshake_m"] > 0.12
    assert partner["slower_than_0_1_m_per_s_from_frame"] <= hs["first_frame"] + hs["frames_in"]
    assert all(abs(v) < 30 for v in partner["last_frame_facing_off_the_other_deg"].values())
    assert 12 <= info["n_frames"] - hs["first_frame"] <= 18
    assert_hands_shaken(d, hs)


def assert_hands_shaken(d, hs):
    """Both right wrists meet midway between the actors, a clasp apart, at waist to chest height, over the held frames
    to the end of the take, and are well apart before the handshake starts."""
    names, _, P = load_gt(d, "gt_joints_Lead.npz")
    _, _, P2 = load_gt(d, "gt_joints_Partner.npz")
    i = {n: k for k, n in enumerate(names)}
    held = np.arange(hs["held_frames"][0], hs["held_frames"][1] + 1)
    assert held[-1] == len(P) - 1
    wrists = np.linalg.norm(P2[:, i["RightHand"]] - P[:, i["RightHand"]], axis=1)
    assert np.all(wrists[held] < 0.15) and np.all(wrists[:hs["first_frame"]] > 0.4)
    hips = np.linalg.norm(P2[held, i["Hips"], :2] - P[held, i["Hips"], :2], axis=1)
    assert np.all((hips > 0.8) & (hips < 1.0))
    meet = (P[held, i["RightHand"]] + P2[held, i["RightHand"]]) / 2
    assert np.all((meet[:, 2] > 0.9) & (meet[:, 2] < 1.3))
    midway = (P[held, i["Hips"], :2] + P2[held, i["Hips"], :2]) / 2
    assert np.linalg.norm(meet[:, :2] - midway, axis=1).max() < 0.15


# ---- duet_dev, handshake_dev: DEVELOPMENT scenes of two actors (tuned on; the held-out duet judges) -------------
@pytest.mark.parametrize("scene", ["duet_dev", "handshake_dev"])
def test_development_duets_are_two_actors_dressed_apart_on_other_material_than_the_held_out_duet(scene):
    """Other clip windows, builds, cameras and clothes than the duet; shirts of clearly different colours; each
    actor hides the other for ten frames or more in some view (duet_dev: never at the first frame)."""
    dev, held = (json.loads((scene_dir(n) / "scene_info.json").read_text()) for n in (scene, "duet"))
    first, last = dev["first_source_frame_30fps"], dev["first_source_frame_30fps"] + dev["n_frames"] - 1
    assert dev["source"] != held["source"] or (last < held["first_source_frame_30fps"]
                                               or first > held["first_source_frame_30fps"] + held["n_frames"] - 1)
    assert dev["partner"]["source"] != held["partner"]["source"]
    for who in ("Lead", "Partner"):
        assert dev["actors"][who]["proportions_from"] != held["actors"][who]["proportions_from"]
        assert dev["actors"][who]["clothing_colours_linear_rgb"] != held["actors"][who]["clothing_colours_linear_rgb"]
    shirts = [dev["actors"][w]["clothing_colours_linear_rgb"]["shirt"] for w in ("Lead", "Partner")]
    assert np.abs(np.subtract(*shirts)).max() > 0.15
    dev_cams, held_cams = (read_calibration(scene_dir(n)) for n in (scene, "duet"))
    assert all(np.linalg.norm(a.center - b.center) > 0.5 for a, b in zip(dev_cams, held_cams))
    for key in ("Lead_hidden_by_Partner", "Partner_hidden_by_Lead"):
        hidden = dev["hidden"][key]
        assert max(v["frames_hidden_over_20_percent"] for v in hidden.values()) >= 10, key
        if scene == "duet_dev":
            assert all(v["hidden_fraction"][0] < 0.05 for v in hidden.values()), key


def test_handshake_dev_actors_shake_hands_standing_apart():
    """The Partner stops facing the Lead before the handshake, 0.8-1.0 m from it, and the right hands meet."""
    d = scene_dir("handshake_dev")
    info = json.loads((d / "scene_info.json").read_text())
    partner, hs = info["partner"], info["handshake"]
    assert partner["slower_than_0_1_m_per_s_from_frame"] <= hs["first_frame"] + hs["frames_in"]
    assert all(abs(v) < 30 for v in partner["last_frame_facing_off_the_other_deg"].values())
    assert hs["wrist_target_miss_when_held_m"] < 0.02
    assert_hands_shaken(d, hs)


# ---- pose2sim_demo: a real capture (no ground truth) ------------------------------------------------
def test_pose2sim_demo_loads_with_one_warning_per_padded_camera():
    import warnings

    from markerless_mocap.core.capture.capture import load_capture

    d = SCENES_ROOT / "pose2sim_demo"
    if not (d / "Calib.qca.txt").is_file():
        pytest.skip(f"{d} not present")
    assert "BSD 3-Clause" in (d / "LICENSE").read_text() and (d / "SOURCE.txt").is_file()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cap = load_capture(d)
    try:
        assert cap.camera_names == ["cam01", "cam02", "cam03", "cam04"]
        assert [c.size for c in cap.cameras] == [(1080, 1920), (1080, 1920), (1088, 1920), (1088, 1920)]
        msgs = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
        assert len(msgs) == 2 and all("1088x1920 but the footage is 1080x1920" in m for m in msgs)
        assert cap.frames.n_frames == 100 and cap.frames.fps == pytest.approx(60.0)
    finally:
        cap.close()


@pytest.mark.bpy
def test_pose2sim_subject_stands_where_the_images_put_the_person(bpy_module):
    bpy = bpy_module
    d = SCENES_ROOT / "pose2sim_demo"
    if not (d / "subject.blend").is_file():
        pytest.skip(f"{d} has no subject.blend")
    info = json.loads((d / "scene_info.json").read_text())
    bpy.ops.wm.open_mainfile(filepath=str(d / "subject.blend"))
    arm = [o for o in bpy.data.objects if o.type == "ARMATURE"][0]
    assert len(arm.data.bones) == 31
    M = np.array(arm.matrix_world)
    hips = M[:3, :3] @ np.array(arm.data.bones["Hips"].head_local) + M[:3, 3]
    assert np.linalg.norm(hips - np.array(info["hips_midpoint_m"])) < 0.20
    yaw = math.degrees(math.atan2(M[1, 0], M[0, 0]))
    assert abs((yaw - info["facing_yaw_deg"] + 180) % 360 - 180) < 1.0


# ---- issue 43's hard motion and issue 44's long take ----------------------------------------------------------
def _clips_the_prior_learns_from():
    from markerless_mocap.core.tracking import motion_library
    data = Path(motion_library.__file__).resolve().parents[1] / "data"
    return {f.name for folder in ("motion", "poses") for f in (data / folder).iterdir()}  # clips and pose excerpts


def test_dance_is_fast_high_and_turning_with_three_cameras_and_an_actor_build():
    """Held out: modern dance from a CMU subject the prior never sees, a leg above hip height while standing on the
    other, hands faster than 6 m/s, more than a full turn; three cameras, an actor 4 % taller than its subject with
    wider shoulders, longer forearms and shorter thighs; busy's room with a second person."""
    d = scene_dir("dance")
    assert len(read_calibration(d)) == 3
    _, ratio = _actor_lengths(d)
    _assert_built(ratio, 1.04, (("forearm", 1.05), ("thigh", 0.96), ("spine", 1.02), ("neck", 0.95)))
    assert ratio["shoulder_width"] > 1.04 * 1.03
    names, _, P = load_gt(d)
    idx = {n: k for k, n in enumerate(names)}
    feet = P[:, [idx["LeftFoot"], idx["RightFoot"]], 2]
    raised = (feet.max(axis=1) > P[:, idx["Hips"], 2]) & (feet.min(axis=1) < 0.15)  # one foot high, one down
    assert raised.sum() >= 2
    hand_speed = np.linalg.norm(np.diff(P[:, [idx["LeftHand"], idx["RightHand"]]], axis=0), axis=-1).max() * 30
    assert hand_speed > 6.0
    info = json.loads((d / "scene_info.json").read_text())
    assert info["source"].startswith("05_") and not any(c.startswith("05_") for c in _clips_the_prior_learns_from())
    assert not (d / "background").exists()
    assert_second_person_in_every_view_and_changing_light("dance", "cam2")


def test_sit_goes_down_onto_a_stool_with_the_knees_above_the_hips():
    """Held out: poses no walking clip has; the hips drop to about half their standing height and the knees rise
    above them, on a stool that stays in the plates."""
    d = scene_dir("sit")
    names, _, P = load_gt(d)
    idx = {n: k for k, n in enumerate(names)}
    hips = P[:, idx["Hips"], 2]
    assert hips[-20:].max() < 0.6 * hips[:5].min()
    knees = P[:, [idx["LeftLeg"], idx["RightLeg"]], 2].min(axis=1)
    assert (knees > hips).sum() >= 20
    info = json.loads((d / "scene_info.json").read_text())
    assert 0.25 < info["seat"]["top_m"] < hips.min()
    assert info["source"].startswith("13_") and not any(c.startswith("13_") for c in _clips_the_prior_learns_from())
    assert (d / "background").is_dir()


def test_long_take_is_long_and_travels():
    d = scene_dir("long")
    names, frames, P = load_gt(d)
    hips = P[:, names.index("Hips"), :2]
    assert len(frames) >= 600
    assert np.linalg.norm(np.diff(hips, axis=0), axis=1).sum() > 8.0   # metres of hips path


# --------------------------------------------------------------- subjects every Blender opens
ALL_SCENES = SCENES + ["pose2sim_demo"]


def _portable_subject():

    from tool_helpers import load_tool

    return load_tool("portable_subject")


@pytest.mark.bpy
@pytest.mark.parametrize("name", ALL_SCENES)
def test_subject_opens_and_is_version_neutral(name):
    """subject.blend is built from the version-neutral subject_source.json.gz by Blender 4.3.2 (a file
    saved by 5.0 does not open in 4.2-4.4; an older file opens in every newer Blender). It opens in this
    bpy (5.0.1 or 5.2.3) and holds exactly the source: bones, rest pose, mesh, weights, materials.
    That it opens in the real 4.3.2 is checked by tests/real_blender/stage.sh."""
    bpy = pytest.importorskip("bpy")
    ps = _portable_subject()
    folder = SCENES_ROOT / name
    source = ps.load_source(folder / "subject_source.json.gz")
    bpy.ops.wm.open_mainfile(filepath=str(folder / "subject.blend"))
    try:
        assert tuple(bpy.data.version[:2]) <= (4, 3), f"{name}/subject.blend saved by {bpy.data.version}"
        got = ps.dump()
    finally:
        bpy.ops.wm.read_homefile(use_empty=True)
    assert got["scene"] == source["scene"] and got["version"] == source["version"]
    subjects, got_subjects = ps.subjects_of(source), ps.subjects_of(got)
    assert [s["armature"]["object"] for s in got_subjects] == [s["armature"]["object"] for s in subjects]
    for subject, got_subject in zip(subjects, got_subjects):
        a, b = subject["armature"], got_subject["armature"]
        assert [x["name"] for x in a["bones"]] == [x["name"] for x in b["bones"]]
        assert [x["parent"] for x in a["bones"]] == [x["parent"] for x in b["bones"]]
        for key in ("head", "tail", "matrix_local"):
            np.testing.assert_allclose([x[key] for x in b["bones"]], [x[key] for x in a["bones"]], atol=2e-6)
        assert b["transform"] == a["transform"] and b["pose"] == a["pose"]
        assert len(got_subject["meshes"]) == len(subject["meshes"]) == 1
        m0, m1 = subject["meshes"][0], got_subject["meshes"][0]
        np.testing.assert_array_equal(m1["vertices"], m0["vertices"])
        for key in ("object", "faces", "smooth", "material_index", "materials", "vertex_groups", "parent",
                    "parent_type", "transform", "modifiers"):
            assert m1[key] == m0[key], key
        for w0, w1 in zip(m0["weights"], m1["weights"]):
            np.testing.assert_allclose(np.reshape(w1, (-1, 2)), np.reshape(w0, (-1, 2)), atol=1e-7)
    assert len(got["materials"]) == len(source["materials"])
    for mat0, mat1 in zip(source["materials"], got["materials"]):
        assert mat1["name"] == mat0["name"] and mat1["diffuse_color"] == mat0["diffuse_color"]
        assert [n["type"] for n in mat1["nodes"]] == [n["type"] for n in mat0["nodes"]]
        assert mat1["links"] == mat0["links"]
        for n0, n1 in zip(mat0["nodes"], mat1["nodes"]):
            for key in set(n0["inputs"]) & set(n1["inputs"]):  # inputs both versions have
                np.testing.assert_allclose(n1["inputs"][key], n0["inputs"][key], atol=1e-6)


@pytest.mark.bpy
def test_portable_subject_round_trips_in_this_blender(tmp_path):
    """dump -> build -> dump gives the same subject (the path generate.py and the resave take)."""
    bpy = pytest.importorskip("bpy")
    ps = _portable_subject()
    source = ps.load_source(SCENES_ROOT / "walk" / "subject_source.json.gz")
    bpy.ops.wm.read_homefile(use_empty=True)
    try:
        ps.build(source)
        again = ps.dump()
    finally:
        bpy.ops.wm.read_homefile(use_empty=True)
    np.testing.assert_allclose([x["matrix_local"] for x in again["armature"]["bones"]],
                               [x["matrix_local"] for x in source["armature"]["bones"]], atol=2e-6)
    assert again["meshes"][0]["faces"] == source["meshes"][0]["faces"]
    assert again["meshes"][0]["weights"] == source["meshes"][0]["weights"]
