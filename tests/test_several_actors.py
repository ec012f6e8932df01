"""Several actors: the silhouette statistics skip the pixels other actors cover (mutual occlusion), checked
against a reference render of both bodies together."""
from pathlib import Path

import numpy as np
import pytest

from markerless_mocap.core import render
from markerless_mocap.core.render import fast, reference

from test_render import look_at, random_blob_targets, sphere_mesh


def _two_bodies_scene():
    verts, faces, labels = sphere_mesh(radius=0.35)
    cams = [look_at("front", [0.0, -3.0, 0.2], [0, 0, 0], 90, 64, 48),
            look_at("side", [3.0, 0.4, 0.1], [0, 0, 0], 80, 56, 48)]
    a_true = verts + [0.15, 0.0, 0.0]
    b_true = verts * [1.0, 1.0, 1.4] + [-0.25, -0.6, 0.05]  # in front of A in "front", beside it in "side"
    return verts, faces, labels, cams, a_true, b_true


def _render(meshes, faces, labels, cam):
    """The reference rasteriser on several meshes at once (one depth test): their joint label image."""
    verts = np.concatenate(meshes)
    all_faces = np.concatenate([faces + i * len(meshes[0]) for i in range(len(meshes))])
    uv, z = render.project_views(verts[None], [cam])
    return reference.rasterize(uv[0, 0], z[0, 0], all_faces, np.tile(labels, len(meshes)), cam.width, cam.height)


def _targets(observed, cams):
    zeros = np.zeros(observed.shape)
    return render.FrameTargets([c.width for c in cams], [c.height for c in cams], observed.astype(np.uint8), zeros,
                               np.ones(observed.shape, np.uint8), zeros, np.zeros(observed.shape + (2,), np.uint8))


@pytest.mark.parametrize("backend", ["numpy", "fast"])
def test_silhouette_xor_with_another_actor_equals_the_joint_render_minus_a_constant(backend):
    # Binary XOR of both bodies rendered together against the image, as a function of A's pose, is A's XOR outside
    # B's pixels plus a constant: what the statistics compute when B's pixels are marked OTHERS.
    verts, faces, labels, cams, a_true, b_true = _two_bodies_scene()
    H, W = 48, 64
    observed = np.zeros((2, H, W), bool)
    b_mask = np.zeros((2, H, W), bool)
    for c, cam in enumerate(cams):
        observed[c, :cam.height, :cam.width] = _render([a_true, b_true], faces, labels, cam) > 0
        b_mask[c, :cam.height, :cam.width] = _render([b_true], faces, labels, cam) > 0
    assert (observed & b_mask).sum() < observed.sum()  # A shows somewhere
    targets = _targets(observed, cams).with_others(b_mask)
    assert targets.has_others and np.array_equal(targets.observed_count, (observed & ~b_mask).sum(axis=(1, 2)))
    rng = np.random.default_rng(5)
    candidates = [a_true] + [a_true + rng.normal(0, 0.12, 3) for _ in range(6)] + [a_true + [-0.4, -0.6, 0.0]]
    uv, z = render.project_views(np.array(candidates), cams)
    stats, _ = render.statistics(uv, z, faces, labels, targets, need_chamfer=False, backend=backend)
    xor = stats[..., render.TEMPLATE] + targets.observed_count[None] - 2 * stats[..., render.OVERLAP]
    for p, cand in enumerate(candidates):
        for c, cam in enumerate(cams):
            joint = _render([cand, b_true], faces, labels, cam) > 0
            obs = observed[c, :cam.height, :cam.width]
            constant = (b_mask[c, :cam.height, :cam.width] & ~obs).sum()
            assert xor[p, c] == (joint ^ obs).sum() - constant
    assert np.all(xor[0] == 0)  # the true pose explains the image exactly: the crossing costs it nothing
    # without the other actor marked, the same true pose pays for B's pixels
    plain, _ = render.statistics(uv[:1], z[:1], faces, labels, _targets(observed, cams), need_chamfer=False,
                                 backend=backend)
    assert np.all(plain[0, :, render.TEMPLATE] + observed.sum(axis=(1, 2)) - 2 * plain[0, :, render.OVERLAP] > 0)


def test_fast_path_equals_reference_with_other_actors_pixels():
    verts, faces, labels = sphere_mesh()
    rng = np.random.default_rng(11)
    cams = [look_at("a", [2.5, 0.3, 0.4], [0, 0, 0], 120, 64, 48),
            look_at("b", [-0.5, 2.2, -0.3], [0, 0, 0], 90, 40, 56)]
    targets = random_blob_targets(cams, rng)
    others = np.zeros(targets.silhouette.shape, bool)
    others[0, 10:30, 20:50] = True
    others[1, 25:56, 0:18] = True
    marked = targets.with_others(others)
    poses = [verts @ np.linalg.qr(rng.normal(size=(3, 3)))[0].T * rng.uniform(0.7, 1.5) + rng.normal(0, 0.3, 3)
             for _ in range(10)]
    uv, z = render.project_views(np.array(poses), cams)
    s_ref, h_ref = reference.statistics(uv, z, faces, labels, marked, True, 3, 0)
    s_fast, h_fast = fast.statistics(uv, z, faces, labels, marked, True, 3, 0)
    assert np.allclose(s_ref, s_fast, rtol=1e-12, atol=1e-9)
    assert np.array_equal(h_ref, h_fast)
    s_plain, _ = reference.statistics(uv, z, faces, labels, targets, True, 3, 0)
    assert np.all(s_ref[..., render.TEMPLATE] <= s_plain[..., render.TEMPLATE])
    assert np.any(s_ref[..., render.TEMPLATE] < s_plain[..., render.TEMPLATE])  # the marked pixels were skipped
    assert np.all(marked.edge_off[others] == 0)
    with pytest.raises(render.RenderInputError, match="other actors"):
        targets.with_others(others[:1])


# ------------------------------------------------------------------------------------------ landmarks of another
def test_another_actors_landmarks_in_one_view_do_not_move_the_fit():
    """The single-person landmark model put the other actor's landmarks in view 0 (the crop shared by both) and one
    wrist of view 1 on the other's: set apart, the fit equals the fit on the clean landmarks alone; kept, it moves."""
    pytest.importorskip("bpy")
    from scene_helpers import mean_joint_error, walk_with_another_person

    from markerless_mocap.core.evidence.keypoint_fit import pose_from_keypoints
    from markerless_mocap.core.evidence.keypoints import KeypointTargets
    from markerless_mocap.core.evidence.learned import CROP_MARGIN
    from markerless_mocap.core.tracking.other_actors import associate_landmarks

    body, cameras, rig, truth, predicted, points, theirs = walk_with_another_person()
    uv = points(truth)
    uv[0] = theirs[0]
    wrist = int(np.nonzero(rig.landmarks == 15)[0][0])  # the left wrist's rig point
    uv[1, wrist] = theirs[1, wrist]
    n = len(rig.landmarks)
    targets = KeypointTargets(uv, np.full((len(cameras), n), 0.95), np.full(len(cameras), 200.0 / CROP_MARGIN))
    clean = KeypointTargets(points(truth), targets.weight.copy(), targets.person_px)
    clean.weight[0] = 0.0
    clean.weight[1, wrist] = 0.0

    kept, taken = associate_landmarks(targets, points(predicted), theirs[None], rig.swap)
    assert taken.tolist() == [True] + [False] * (len(cameras) - 1)
    assert np.array_equal(kept.weight, clean.weight)
    start = predicted.copy()
    fit_kept = pose_from_keypoints(body, cameras, kept, rig, start)[0]
    fit_clean = pose_from_keypoints(body, cameras, clean, rig, start)[0]
    fit_all = pose_from_keypoints(body, cameras, targets, rig, start)[0]
    assert mean_joint_error(body, fit_kept, fit_clean) < 1e-6
    assert mean_joint_error(body, fit_kept, truth) < 0.02
    assert mean_joint_error(body, fit_all, truth) > 2 * mean_joint_error(body, fit_kept, truth) + 0.01


# ------------------------------------------------------------------------------------------ the command line
def test_track_with_two_armatures_keys_each_on_its_own_person(tmp_path, capsys):
    """`track --armature Lead --armature Partner` on the duet's frames 0-12: one result folder per actor, each
    actor's hips on its own person (not the other's), OUT/report.json listing both; the Partner's first frame,
    searched with its legs the wrong way round, replaced once its second frame is solved; and the take ends
    naming, per actor, the views whose landmarks were the other actor's (the Lead hides the Partner in cam3)."""
    pytest.importorskip("bpy")
    import json

    from scene_helpers import scene_dir

    from markerless_mocap.core.results.result_folder import load_joints
    from markerless_mocap.operators.cli import main

    duet = scene_dir("duet")
    out = tmp_path / "out"
    # the full landmark model: with it the Partner's first search has the legs the wrong way round, the review's
    # case (with the default heavy model the first search needs no review on these frames)
    code = main(["track", "--scene", str(duet / "subject.blend"), "--capture", str(duet), "--out", str(out),
                 "--frames", "0-12", "--armature", "Lead", "--armature", "Partner", "--no-overlays", "--no-export",
                 "--seed", "0", "--landmarks", "full"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    report = json.loads((out / "report.json").read_text())
    assert [a["armature"] for a in report["actors"]] == ["Lead", "Partner"]
    assert all(a["frames_solved"] == 13 for a in report["actors"])
    truths = {name: load_joints(duet / f"gt_joints_{name}.npz") for name in ("Lead", "Partner")}
    for name, other in (("Lead", "Partner"), ("Partner", "Lead")):
        names, frames, solved = load_joints(out / "actors" / name / "joints_raw.npz")
        assert list(frames) == list(range(13))
        hips = solved[:, list(names).index("Hips")]
        own = truths[name][2][:13, list(truths[name][0]).index("Hips")]
        theirs = truths[other][2][:13, list(truths[other][0]).index("Hips")]
        assert np.linalg.norm(hips - own, axis=1).max() < 0.1
        assert np.all(np.linalg.norm(hips - theirs, axis=1) > 0.3)
    # measured: the first search's knees 0.35 m and ankles 0.55-0.61 m off; reviewed, 0.02-0.07 m
    review = json.loads((out / "actors" / "Partner" / "report.json").read_text()).get("first_frame_review")
    assert review is not None and review["frame"] == 0, review
    names, _, solved = load_joints(out / "actors" / "Partner" / "joints_raw.npz")
    truth_names, _, truth = truths["Partner"]
    legs = ["LeftLeg", "RightLeg", "LeftFoot", "RightFoot"]
    off = [np.linalg.norm(solved[0, list(names).index(b)] - truth[0, list(truth_names).index(b)]) for b in legs]
    assert max(off) < 0.15, dict(zip(legs, np.round(off, 3)))
    said = printed.out + printed.err
    assert "Partner: landmarks left out: cam3 on frames" in said, said[-2000:]
    # `evaluate` on the whole result without ground truth (real footage): each actor against the evidence around its
    # own pose, on its own armature; both drawn on one contact sheet; a truth file, one person's, asks for an actor
    code = main(["evaluate", "--result", str(out), "--capture", str(duet), "--sheet", str(tmp_path / "sheet.png"),
                 "--every", "12"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    agreement = [json.loads(line) for line in printed.out.splitlines() if line.startswith("{")]
    assert [a["result"].rsplit("/", 1)[-1] for a in agreement] == ["Lead", "Partner"], printed.out
    assert all(a["frames"] == 13 and a["agreement"]["all"]["iou"] > 0.6 for a in agreement), agreement
    import cv2

    assert cv2.imread(str(tmp_path / "sheet.png")).shape[0] > 0
    assert main(["evaluate", "--result", str(out), "--truth", str(duet / "gt_joints_Lead.npz")]) == 2
    assert f"or one actor's folder with its truth, --result {out / 'actors' / 'Lead'}" in capsys.readouterr().err
    # with the folder of every actor's truth (gt_joints_<armature>.npz), each actor against its own
    assert main(["evaluate", "--result", str(out), "--truth", str(duet)]) == 0
    measured = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    assert [Path(m["result"]).name for m in measured] == ["Lead", "Partner"]
    assert all(m["frames"] == 13 and m["mean_mm"] < 100 for m in measured), measured


def test_several_actors_ask_whose_measurement_and_refuse_names_that_share_a_folder(tmp_path, capsys):
    pytest.importorskip("bpy")
    from scene_helpers import scene_dir

    from markerless_mocap.operators.cast_session import actor_folder_name
    from markerless_mocap.operators.cli import main

    duet = scene_dir("duet")
    code = main(["track", "--scene", str(duet / "subject.blend"), "--capture", str(duet), "--out",
                 str(tmp_path / "o"), "--frames", "0-2", "--armature", "Lead", "--armature", "Partner",
                 "--calibrate-measured", "height=1.7"])
    assert code == 2  # whose height it is, said before anything is fitted or tracked
    assert "with several armatures say whose it is, as in --calibrate-measured Partner:" in capsys.readouterr().err
    code = main(["track", "--scene", str(duet / "subject.blend"), "--capture", str(duet), "--out",
                 str(tmp_path / "o"), "--frames", "0-2", "--armature", "Lead", "--armature", "Lead"])
    assert code == 2 and "an armature is given twice (Lead, Lead)" in capsys.readouterr().err
    assert not (tmp_path / "o" / "actors").exists()
    assert actor_folder_name("Lead/1") == actor_folder_name("Lead:1") == "Lead_1"
    assert actor_folder_name("..") == "armature"


# ------------------------------------------------------------------------------------------ the Track panel
@pytest.mark.bpy
def test_track_panel_with_every_armature_keys_both(addon_module_name, bpy_module, tmp_path, monkeypatch):
    """Subject panel: 'Track Every Armature' with two armatures in the scene; Track keys both, each on its own
    person, writes actors/<armature>/ and one tracked.blend; a cluster run is refused with the fix."""
    from scene_helpers import scene_dir
    from test_addon_ui import _draw_all, _labels

    bpy = bpy_module
    duet = scene_dir("duet")
    bpy.ops.wm.open_mainfile(filepath=str(duet / "subject.blend"))
    m = bpy.context.scene.mocap
    text = " ".join(_labels(_draw_all(bpy, panels=("MOCAP_PT_subject",))))
    assert "pick the one to track" in text
    m.every_armature = True
    text = " ".join(_labels(_draw_all(bpy, panels=("MOCAP_PT_subject",))))
    assert "Tracks 2 actors at once: Lead, Partner" in text and "pick the one" not in text
    # each armature's tick says whether it is an actor (a character only receiving motion is unticked)
    from markerless_mocap.operators.setup_subject import subject_armatures

    objects = bpy.context.scene.objects
    objects["Partner"].mocap_actor = False
    assert "Tracks Lead alone" in " ".join(_labels(_draw_all(bpy, panels=("MOCAP_PT_subject",))))
    assert [o.name for o in subject_armatures(bpy.context)] == ["Lead"]
    objects["Lead"].mocap_actor = False
    assert "No armature ticked" in " ".join(_labels(_draw_all(bpy, panels=("MOCAP_PT_subject",))))
    m.capture_dir = str(duet)
    with pytest.raises(RuntimeError, match="no armature is ticked as an actor"):
        bpy.ops.mocap.track()
    objects["Lead"].mocap_actor = objects["Partner"].mocap_actor = True
    m.output_dir = str(tmp_path / "out")
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 1
    m.preset = "preview"
    assert bpy.ops.mocap.track() == {"FINISHED"}, m.last_error
    for name in ("Lead", "Partner"):
        arm = bpy.context.scene.objects[name]
        assert arm.animation_data is not None and arm.animation_data.action is not None  # keyed
        assert (tmp_path / "out" / "actors" / name / "joints.npz").is_file()
    assert (tmp_path / "out" / "tracked.blend").is_file()
    assert (tmp_path / "out" / "overlay" / "cam1.mp4").is_file()

    # Run On local processes: one take of both actors goes to the batch, with each actor's measured lengths, and
    # each actor's result is keyed on its own armature when the batch is done (the batch here: this result)
    from test_addon_ui import _EndedProcess, _write_progress

    import importlib

    cmd_batch = importlib.import_module(f"{addon_module_name}.operators.cmd_batch")
    track_batch = importlib.import_module(f"{addon_module_name}.operators.track_batch")
    sent = {}

    def fake_launch(takes, out_dir, **kwargs):
        sent.update(takes=takes)
        _write_progress(out_dir, "done", [{"name": takes[0]["name"], "state": "done", "chunks_done": 1,
                                           "chunks_total": 1, "frames": [0, 1], "result": str(tmp_path / "out"),
                                           "error": None}], chunks=(1, 1))
        return _EndedProcess(0)

    monkeypatch.setattr(cmd_batch, "launch_batch", fake_launch)
    for name in ("Lead", "Partner"):
        bpy.context.scene.objects[name].animation_data_clear()
    objects["Partner"].mocap_measured.actor_height = 1.62
    m.run_on = "local"
    assert bpy.ops.mocap.track() == {"FINISHED"}, m.last_error
    (take,) = sent["takes"]
    assert take["armature"] == ["Lead", "Partner"] and take["measured"] == ["Partner:height=1.62"], take
    while bpy.context.scene.name in track_batch._RUNS:
        track_batch.poll(bpy.context.scene.name)
    assert m.last_error == "" and m.status.startswith("Tracked 2 frames in 1 chunk in "), (m.status, m.last_error)
    for name in ("Lead", "Partner"):
        arm = bpy.context.scene.objects[name]
        assert arm.animation_data is not None and arm.animation_data.action is not None, name  # keyed again


def test_the_other_actors_masks_fast_path_covers_the_reference_rasterisers_pixels():
    from markerless_mocap.core.tracking import other_actors

    verts, faces, labels, cams, a_true, b_true = _two_bodies_scene()
    uv, z = render.project_views(np.array([a_true, b_true]), cams)
    for p in range(2):
        for c, cam in enumerate(cams):
            fast_mask = other_actors._drawn(uv[p, c], z[p, c], faces, cam.width, cam.height)
            reference_mask = reference.rasterize(uv[p, c], z[p, c], faces, labels, cam.width, cam.height) > 0
            assert reference_mask.sum() > 50
            assert (fast_mask != reference_mask).sum() <= 0.01 * reference_mask.sum()  # ties on triangle edges


def test_where_two_hands_meet_the_landmark_stays_with_both_actors():
    """A handshake: one wrist landmark a pixel from the other actor's hand and 3 px from this actor's predicted
    wrist is kept for both (the other's nearer point does not take it); 40 px away from this actor's it is the
    other's."""
    from markerless_mocap.core.tracking.other_actors import closer_to_others

    own = np.zeros((1, 2, 2))
    own[0, 1] = [100.0, 100.0]                      # this actor's predicted wrist (point 1); point 0 far away
    other = np.full((1, 1, 2, 2), 1000.0)
    other[0, 0, 1] = [102.0, 100.0]                 # the other actor's hand, two pixels on
    swap = np.array([0, 1])
    near = np.zeros((1, 2, 2))
    near[0, 1] = [103.0, 100.0]
    assert not closer_to_others(near, own, other, swap, own_tolerance=[16.0])[0, 1]
    assert closer_to_others(near, own, other, swap)[0, 1]  # without the tolerance the other takes it
    far_own = own.copy()
    far_own[0, 1] = [60.0, 100.0]
    assert closer_to_others(near, far_own, other, swap, own_tolerance=[16.0])[0, 1]
