"""Actor proportions (issue 15): the scaled body, and the fit that recovers it from landmarks."""
import numpy as np
import pytest

from markerless_mocap.core.capture.calibration import read_calibration
from markerless_mocap.core.evidence.keypoints import rig_keypoints
from markerless_mocap.core.actor.proportions import Proportions, ProportionsError, scaled_body, segment_lengths
from markerless_mocap.core.actor.landmark_fit import fit_proportions, proportions_for_lengths

from scene_helpers import ground_truth_poses, scene_dir

ACTOR = Proportions({"forearm": 0.92 * 1.10, "thigh": 0.95, "shoulder_width": 0.97}, 0.92)


@pytest.fixture
def walk(bpy_module):
    body, frames, poses, _ = ground_truth_poses("walk")  # cached across tests
    return body, poses


def test_scaled_body_lengths_follow_the_factors(walk):
    body, _ = walk
    actor = scaled_body(body, ACTOR)
    a, s = segment_lengths(actor), segment_lengths(body)
    assert a["forearm"] / s["forearm"] == pytest.approx(0.92 * 1.10, rel=1e-9)
    assert a["thigh"] / s["thigh"] == pytest.approx(0.95, rel=1e-9)
    assert a["upper_arm"] / s["upper_arm"] == pytest.approx(0.92, rel=1e-9)
    assert a["neck"] / s["neck"] == pytest.approx(0.92, rel=1e-9)
    # the scaled body stands on the same floor and is shorter by about the overall factor
    up = np.array([0.0, 0.0, 1.0])
    world = lambda b: b.vertices @ b.skeleton.armature_matrix[:3, :3].T + b.skeleton.armature_matrix[:3, 3]
    assert (world(actor) @ up).min() == pytest.approx((world(body) @ up).min(), abs=1e-9)
    assert 0.90 < a["height"] / s["height"] < 0.94


def test_scaled_body_skin_follows_its_bones(walk):
    """FK + LBS of the scaled body: each vertex keeps its place relative to the bones that carry it, so the
    posed skin of a longer forearm still ends at the (moved) hand."""
    body, poses = walk
    actor = scaled_body(body, ACTOR)
    main = np.argmax(body.weights, axis=1)
    rigid = np.nonzero(body.weights.max(axis=1) > 1 - 1e-9)[0]  # vertices carried by one bone alone
    assert len(rigid) > 100
    x = poses[10:11]
    for b in (body, actor):
        v = b.deform(x)[0][rigid]
        M = b.pose_matrices(x)[0, main[rigid]]
        local = np.einsum("vji,vj->vi", M[:, :3, :3], v - M[:, :3, 3])
        R = b.skeleton.rest[main[rigid]]
        rest_local = np.einsum("vji,vj->vi", R[:, :3, :3], b.vertices[rigid] - R[:, :3, 3])
        np.testing.assert_allclose(local, rest_local, rtol=0, atol=1e-6)
    # the head's skin is only resized by the overall factor (it keeps its shape)
    head = np.nonzero(main == body.skeleton.index["Head"])[0]
    assert len(head) > 20
    size = lambda b: np.ptp(b.vertices[head], axis=0).max()
    assert size(actor) / size(body) == pytest.approx(0.92, rel=0.03)


def test_bad_factor_is_refused_with_the_fix():
    with pytest.raises(ProportionsError, match="outside 0.5-2.0"):
        Proportions({"forearm": 3.0})
    with pytest.raises(ProportionsError, match="unknown segment 'tail'"):
        Proportions({"tail": 1.0})


def _synthetic_landmarks(actor, cameras, poses, rng, noise_px):
    rig = rig_keypoints(actor)
    world = rig.world(actor, poses)
    uv = np.zeros((len(poses), len(cameras), 33, 2))
    vis = np.zeros((len(poses), len(cameras), 33))
    for c, cam in enumerate(cameras):
        p = cam.project(world.reshape(-1, 3)).reshape(len(poses), -1, 2)
        uv[:, c, rig.landmarks] = p + rng.normal(0, noise_px, p.shape)
        vis[:, c, rig.landmarks] = 0.9
    return uv, vis


def test_fit_recovers_known_proportions_from_landmarks(walk):
    """Landmarks projected from a scaled body (1.5 px noise) into the walk cameras, the subject's true poses
    as starting points: every fitted segment within 3 % of the truth, and the residual drops."""
    body, poses = walk
    actor = scaled_body(body, ACTOR)
    cameras = read_calibration(scene_dir("walk"))
    frames = np.arange(0, 60, 10)
    uv, vis = _synthetic_landmarks(actor, cameras, poses[frames], np.random.default_rng(0), 1.5)
    fit = fit_proportions(body, cameras, uv, vis, poses[frames], frames=frames)
    truth = segment_lengths(actor)
    for seg in ("spine", "shoulder_width", "upper_arm", "forearm", "hip_width", "thigh", "shin", "height"):
        assert fit.lengths[seg] == pytest.approx(truth[seg], rel=0.03), seg
    assert fit.rms_after < 0.5 * fit.rms_before
    # and the same fit on the unscaled subject's own landmarks stays at 1 (no drift)
    uv, vis = _synthetic_landmarks(body, cameras, poses[frames], np.random.default_rng(1), 1.5)
    fit = fit_proportions(body, cameras, uv, vis, poses[frames], frames=frames)
    for seg in ("upper_arm", "forearm", "thigh", "shin"):
        assert fit.proportions.factor(seg) == pytest.approx(1.0, abs=0.02), seg


def test_measured_lengths_replace_the_calibrated_ones(walk):
    """A measured forearm gives the body exactly that forearm and leaves every other segment as calibrated; a
    measured height scales the whole body to it first; with sided factors both sides take the measurement."""
    from markerless_mocap.core.actor.measured_lengths import measured_proportions

    body, _ = walk
    before = segment_lengths(scaled_body(body, ACTOR))
    after = segment_lengths(scaled_body(body, measured_proportions(body, ACTOR, {"forearm": 0.25})))
    assert after["forearm"] == pytest.approx(0.25, rel=1e-6)
    for seg in ("height", "spine", "neck", "shoulder_width", "upper_arm", "hip_width", "thigh", "shin", "foot"):
        assert after[seg] == pytest.approx(before[seg], rel=1e-9), seg
    both = segment_lengths(scaled_body(body, measured_proportions(body, ACTOR, {"height": 1.60,
                                                                                "shoulder_width": 0.36})))
    assert both["height"] == pytest.approx(1.60, rel=1e-6) and both["shoulder_width"] == pytest.approx(0.36, rel=1e-6)
    scale = 1.60 / before["height"]
    for seg in ("spine", "upper_arm", "forearm", "thigh"):
        assert both[seg] == pytest.approx(before[seg] * scale, rel=1e-6), seg
    sided = Proportions({"l_forearm": 0.95, "r_forearm": 1.05, "thigh": 0.97}, 0.97)
    got = segment_lengths(scaled_body(body, measured_proportions(body, sided, {"forearm": 0.24})))
    assert got["l_forearm"] == pytest.approx(0.24, rel=1e-6) and got["r_forearm"] == pytest.approx(0.24, rel=1e-6)


def test_lengths_carry_over_to_another_rig(walk):
    body, _ = walk
    target = segment_lengths(scaled_body(body, ACTOR))
    other = scaled_body(body, Proportions.uniform(1.1))  # a bigger character receives the actor's lengths
    got = segment_lengths(scaled_body(other, proportions_for_lengths(other, target)))
    for seg in ("spine", "neck", "shoulder_width", "upper_arm", "forearm", "hip_width", "thigh", "shin", "foot"):
        assert got[seg] == pytest.approx(target[seg], rel=2e-3), seg


def test_a_calibration_that_kept_the_rig_tracks_the_rig_itself(walk, tmp_path):
    """actor_body of a calibration whose every factor is 1 is the rig's own body (the take is then the uncalibrated
    one to the last bit); any other calibration a scaled copy."""
    from markerless_mocap.core.actor.actor_file import actor_body, load_actor, save_actor
    from markerless_mocap.core.actor.landmark_fit import ProportionsFit

    body, _ = walk
    lengths = segment_lengths(body)
    for proportions, is_rig in ((Proportions({k: 1.0 for k in ("forearm", "thigh")}, 1.0), True), (ACTOR, False)):
        fit = ProportionsFit(proportions, segment_lengths(scaled_body(body, proportions)), lengths, [0, 1, 2], 0.02,
                             0.01, np.zeros((3, body.n_dof)))
        data = load_actor(save_actor(tmp_path / "actor.json", fit))
        assert (actor_body(data, body) is body) == is_rig
    assert segment_lengths(actor_body(data, body))["thigh"] == pytest.approx(0.95 * lengths["thigh"], rel=1e-9)


def _synthetic_masks(actor, cameras, poses):
    """The actor's silhouettes (its mesh simplified to 8000 triangles, not the tracker's 2000) per frame and view."""
    from markerless_mocap.core import render
    from markerless_mocap.core.body.proxy import make_proxy

    proxy = make_proxy(actor, 8000)
    verts = proxy.deform(actor, poses)
    uv, z = render.project_views(verts, cameras)
    faces = np.ascontiguousarray(proxy.faces, np.int64)
    label = (np.asarray(proxy.face_part) + 1).astype(np.int16)
    return [[render.render_view(uv[f, c], z[f, c], faces, label, cam.width, cam.height)[1]
             for c, cam in enumerate(cameras)] for f in range(len(poses))]


def test_silhouettes_find_the_forearm_and_hips_the_landmarks_missed(walk):
    """Masks of an actor 8 % smaller with 10 % longer forearms and 10 % narrower hips; the refinement starts
    from the body a landmark fit that missed both would give (every segment at 0.92), at the true poses:
    the forearm and hip width come out within 3 % of the truth, the mask mismatch drops, and the segments
    the masks do not refine keep the landmark fit's length. From the truth itself, nothing moves beyond 1 %."""
    from markerless_mocap.core.actor.silhouette_fit import SILHOUETTE_SEGMENTS, refine_proportions
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses = walk
    truth = Proportions({"forearm": 0.92 * 1.10, "hip_width": 0.92 * 0.90}, 0.92)
    actor = scaled_body(body, truth)
    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 10)
    masks = _synthetic_masks(actor, cameras, poses[frames])
    proxy = make_proxy(body, 2000)
    start = Proportions({s: 0.92 for s in ("spine", "neck", "shoulder_width", "upper_arm", "forearm",
                                           "hip_width", "thigh", "shin", "foot")}, 0.92)
    out = refine_proportions(body, proxy, cameras, masks, poses[frames], start, backend="fast",
                             segments=SILHOUETTE_SEGMENTS)
    got, want = segment_lengths(scaled_body(body, out.proportions)), segment_lengths(actor)
    assert got["forearm"] == pytest.approx(want["forearm"], rel=0.03)
    assert got["hip_width"] == pytest.approx(want["hip_width"], rel=0.03)
    assert out.cost_after < 0.8 * out.cost_before
    for seg in ("spine", "upper_arm", "thigh", "shin"):
        assert out.proportions.factor(seg) == 0.92, seg
    same = refine_proportions(body, proxy, cameras, masks, poses[frames], truth, backend="fast",
                              segments=SILHOUETTE_SEGMENTS)
    for seg in SILHOUETTE_SEGMENTS:
        assert same.proportions.factor(seg) == pytest.approx(truth.factor(seg), rel=0.01), seg


def test_a_length_the_masks_push_past_the_bound_keeps_the_landmark_fit(walk):
    """Masks of forearms 25 % longer than the start (more than the landmarks were ever seen to miss): the
    optimum lies at the bound around the landmark fit, so the forearm keeps the landmark length and is
    reported as kept, while the hip width (10 % off) is still refined."""
    from markerless_mocap.core.actor.silhouette_fit import SILHOUETTE_SEGMENTS, refine_proportions
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses = walk
    truth = Proportions({"forearm": 0.92 * 1.25, "hip_width": 0.92 * 0.90}, 0.92)
    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 10)
    masks = _synthetic_masks(scaled_body(body, truth), cameras, poses[frames])
    start = Proportions({s: 0.92 for s in ("spine", "neck", "shoulder_width", "upper_arm", "forearm",
                                           "hip_width", "thigh", "shin", "foot")}, 0.92)
    out = refine_proportions(body, make_proxy(body, 2000), cameras, masks, poses[frames], start, backend="fast",
                             segments=SILHOUETTE_SEGMENTS)
    assert out.kept == ["forearm"] and out.proportions.factor("forearm") == 0.92
    assert out.proportions.factor("hip_width") == pytest.approx(truth.factor("hip_width"), rel=0.03)


def test_the_masks_choose_between_the_rig_and_the_halfway_body(walk):
    """The choice of core/actor/body_choice.py on synthetic masks, each body's poses refitted from the true ones
    pushed off by a few degrees: masks of the rig itself rank the rig above a body 8 % larger; masks of an actor
    8 % smaller rank that body above the rig. The halfway body takes each segment's deviation from the uniform
    scale to the fitted height halfway; keep_chosen gives the chosen body and keeps the fit on record."""
    from markerless_mocap.core.actor.body_choice import (BodyComparison, candidate_bodies, keep_chosen, mask_mismatch,
                                                         uniform_body)
    from markerless_mocap.core.actor.landmark_fit import ProportionsFit
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses = walk
    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 15)
    start = poses[frames] + np.random.default_rng(3).normal(0.0, 0.03, poses[frames].shape)
    proxy = make_proxy(body, 2000)
    rig, bigger, smaller = Proportions({}, 1.0), Proportions.uniform(1.08), Proportions.uniform(0.92)
    on_rig = mask_mismatch(body, proxy, cameras, _synthetic_masks(body, cameras, poses[frames]),
                           [(rig, start), (bigger, start)], backend="fast")
    assert on_rig[0] < on_rig[1], on_rig
    on_actor = mask_mismatch(body, proxy, cameras, _synthetic_masks(scaled_body(body, smaller), cameras, poses[frames]),
                             [(rig, start), (smaller, start)], backend="fast")
    assert on_actor[1] < on_actor[0], on_actor

    fitted = Proportions({"spine": 1.10, "thigh": 0.90, "forearm": 1.0}, 1.0)
    lengths = segment_lengths(scaled_body(body, fitted))
    fit = ProportionsFit(fitted, lengths, segment_lengths(body), list(frames), 0.03, 0.02, poses[frames], {})
    bodies = candidate_bodies(fit)
    scale = lengths["height"] / segment_lengths(body)["height"]
    assert list(bodies) == ["rig", "halfway"] and set(bodies["rig"].factors.values()) == {1.0}
    assert bodies["halfway"].factors["spine"] == pytest.approx(np.sqrt(1.10 * scale))
    assert bodies["halfway"].factors["thigh"] == pytest.approx(np.sqrt(0.90 * scale))
    kept_rig = keep_chosen(fit, body, BodyComparison({"rig": on_rig[0], "halfway": on_rig[1]}))
    assert kept_rig.proportions.overall == 1.0 and kept_rig.lengths == fit.subject_lengths
    check = kept_rig.silhouettes["body_check"]
    assert check["chosen"] == "rig" and check["fitted_lengths_m"]["height"] == pytest.approx(lengths["height"])
    halfway = keep_chosen(fit, body, BodyComparison({"rig": on_actor[0], "halfway": on_actor[1]}))
    assert halfway.silhouettes["body_check"]["chosen"] == "halfway"
    assert halfway.silhouettes["body_check"]["fitted_factors"] == fitted.factors
    assert halfway.lengths["spine"] == pytest.approx(segment_lengths(scaled_body(body, bodies["halfway"]))["spine"])
    assert lengths["spine"] > halfway.lengths["spine"] > segment_lengths(body)["spine"] * scale
    assert halfway.lengths["height"] == pytest.approx(lengths["height"], rel=0.01)
    # where the masks read the height otherwise than the landmarks, the rig scaled to the masks' height competes
    uniform = uniform_body(fit, 1.80)
    assert uniform.factors.keys() == fitted.factors.keys() and uniform.overall == pytest.approx(
        1.80 / segment_lengths(body)["height"])
    scaled = keep_chosen(fit, body, BodyComparison({"rig": 0.3, "uniform": 0.2}, {**bodies, "uniform": uniform}))
    assert scaled.silhouettes["body_check"]["chosen"] == "uniform"
    assert scaled.lengths["height"] == pytest.approx(1.80, rel=1e-6)


def test_the_body_choice_scores_each_body_once(walk, monkeypatch):
    """compare_bodies' searches (split, hip width, height) and the final choice end on bodies already scored (the
    height's grid centre is the body chosen): each body's frames are refitted once, and the costs are those of
    scoring every body afresh."""
    from types import SimpleNamespace

    from markerless_mocap.core.actor import body_choice as calibration_check
    from markerless_mocap.core.actor.landmark_fit import ProportionsFit

    body, poses = walk
    fitted = Proportions({"spine": 1.06, "thigh": 0.95, "forearm": 1.04, "hip_width": 0.97}, 1.0)
    lengths = segment_lengths(scaled_body(body, fitted))
    fit = ProportionsFit(fitted, lengths, segment_lengths(body), [0, 1, 2], 0.03, 0.02, poses[:3], {})
    target = {"spine": 0.02, "thigh": -0.01, "hip_width": 0.02}  # log-factors the fake masks like best

    def cost(p):
        return sum((np.log(p.factors.get(k, 1.0)) - target.get(k, 0.0)) ** 2 for k in p.factors) + np.log(
            p.overall) ** 2

    scored = []

    def fake_mask_mismatch(subject, proxy, cameras, masks, candidates, *args):
        scored.extend((tuple(sorted(p.factors.items())), p.overall) for p, _ in candidates)
        return [cost(p) for p, _ in candidates]

    monkeypatch.setattr(calibration_check, "mask_mismatch", fake_mask_mismatch)
    targets = SimpleNamespace(cameras=[], masks=[], keypoints=[], resolution=lambda tracker: 1.0)
    tracker = SimpleNamespace(proxy=None, settings=SimpleNamespace(backend="fast", landmarks="full"))
    comparison = calibration_check.compare_bodies(fit, body, tracker, targets, poses[:3])
    assert len(scored) == len(set(scored)), "a body was scored twice"
    assert comparison.split["grid"] and comparison.hip_width["grid"] and comparison.height["grid"]
    for name, proportions in comparison.bodies.items():
        assert comparison.mismatch[name] == pytest.approx(cost(proportions))


def test_the_rig_is_not_kept_where_the_landmarks_and_the_masks_both_read_another_height(walk, monkeypatch):
    """core/actor/body_choice.rig_ruled_out: the rig the masks like best is still set aside where the landmarks' and
    the masks' heights both lie more than RIG_HEIGHT_GATE off the rig's on the same side; the rig scaled to the
    masks' height is taken instead. One reading off, or the two on opposite sides, keep the rig."""
    from types import SimpleNamespace

    from markerless_mocap.core.actor import body_choice, height_by_masks
    from markerless_mocap.core.actor.landmark_fit import ProportionsFit

    gate = body_choice.RIG_HEIGHT_GATE
    assert body_choice.rig_ruled_out(1.70, {"landmark_height_m": 1.64, "masks_height_m": 1.66})
    assert not body_choice.rig_ruled_out(1.70, {"landmark_height_m": 1.64, "masks_height_m": 1.70 * (1 - gate / 2)})
    assert not body_choice.rig_ruled_out(1.70, {"landmark_height_m": 1.64, "masks_height_m": 1.76})

    body, poses = walk
    rig_height = segment_lengths(body)["height"]
    fitted = Proportions({"spine": 0.97, "thigh": 0.95, "forearm": 1.0, "hip_width": 0.98}, 0.96)
    lengths = segment_lengths(scaled_body(body, fitted))
    fit = ProportionsFit(fitted, lengths, segment_lengths(body), [0, 1, 2], 0.03, 0.02, poses[:3], {})

    def mismatch(subject, proxy, cameras, masks, candidates, *args):  # masks that like the rig's height best
        return [abs(np.log(p.overall)) + 0.01 * sum(abs(np.log(f)) for f in p.factors.values()) for p, _ in candidates]

    def compare(masks_height):
        monkeypatch.setattr(height_by_masks, "height_by_masks", lambda subject, start, mismatch: {
            "log_change": 0.0, "grid": [], "landmark_height_m": 0.96 * rig_height, "masks_height_m": masks_height,
            "taken": False})
        monkeypatch.setattr(body_choice, "mask_mismatch", mismatch)
        targets = SimpleNamespace(cameras=[], masks=[], keypoints=[], resolution=lambda tracker: 1.0)
        tracker = SimpleNamespace(proxy=None, settings=SimpleNamespace(backend="fast", landmarks="full"))
        return body_choice.compare_bodies(fit, body, tracker, targets, poses[:3])

    kept = compare(0.99 * rig_height)
    assert kept.chosen == "rig" and "uniform" not in kept.mismatch and not kept.ruled_out
    ruled = compare(0.975 * rig_height)
    assert ruled.mismatch["rig"] < ruled.mismatch["uniform"] and ruled.chosen == "uniform"
    assert ruled.as_dict()["ruled_out"] == ["rig"]
    chosen = body_choice.keep_chosen(fit, body, ruled)
    assert chosen.lengths["height"] == pytest.approx(0.975 * rig_height, rel=1e-6)


def test_the_masks_find_the_trunk_leg_split(walk):
    """core/actor/trunk_leg_split.py: a trade keeps spine + thigh (the standing height) and changes the spine by exp(t);
    on synthetic masks of an actor whose spine is 6 % shorter and thighs longer by the same length, the search
    from the rig's split finds it within 2 % (each candidate's poses refitted from the true ones pushed off)."""
    from markerless_mocap.core.actor.body_choice import mask_mismatch
    from markerless_mocap.core.body.proxy import make_proxy
    from markerless_mocap.core.actor.trunk_leg_split import split_by_masks, traded

    body, poses = walk
    rig = segment_lengths(body)
    start = Proportions({"spine": 1.0, "thigh": 1.0, "shin": 1.0}, 1.0)
    short = traded(start, rig, np.log(0.94))
    got = segment_lengths(scaled_body(body, short))
    assert got["spine"] == pytest.approx(0.94 * rig["spine"], rel=1e-6)
    assert got["spine"] + got["thigh"] == pytest.approx(rig["spine"] + rig["thigh"], rel=1e-6)
    assert got["height"] == pytest.approx(rig["height"], abs=0.005)

    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 15)
    pushed = poses[frames] + np.random.default_rng(5).normal(0.0, 0.02, poses[frames].shape)
    masks = _synthetic_masks(scaled_body(body, short), cameras, poses[frames])
    proxy = make_proxy(body, 2000)
    t, grid = split_by_masks(start, rig, lambda bodies: mask_mismatch(body, proxy, cameras, masks,
                                                                      [(p, pushed) for p in bodies], backend="fast"))
    assert len(grid) == 7 and min(grid, key=grid.get) < 0
    assert t == pytest.approx(np.log(0.94), abs=0.02), grid
    # a mismatch still falling at the grid's end does not pin the split down: the usual split stays
    assert split_by_masks(start, rig, lambda bodies: [-b.factors["spine"] for b in bodies])[0] == 0.0


def test_the_masks_find_the_hip_width(walk):
    """core/actor/hip_width_by_masks.py: on synthetic masks of an actor whose hips are 7 % narrower, the search from the
    rig's hip width finds it within 2.5 % (each candidate's poses refitted from the true ones pushed off); only the
    hip width moves."""
    from markerless_mocap.core.actor.body_choice import mask_mismatch
    from markerless_mocap.core.actor.hip_width_by_masks import hip_width_by_masks, widened
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses = walk
    start = Proportions({"spine": 1.0, "hip_width": 1.0, "thigh": 1.0}, 1.0)
    narrow = widened(start, np.log(0.93))
    assert narrow.factors == {"spine": 1.0, "hip_width": pytest.approx(0.93), "thigh": 1.0}
    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 15)
    pushed = poses[frames] + np.random.default_rng(7).normal(0.0, 0.02, poses[frames].shape)
    masks = _synthetic_masks(scaled_body(body, narrow), cameras, poses[frames])
    proxy = make_proxy(body, 2000)
    t, grid = hip_width_by_masks(start, lambda bodies: mask_mismatch(body, proxy, cameras, masks,
                                                                     [(p, pushed) for p in bodies], backend="fast"))
    assert len(grid) == 9 and min(grid, key=grid.get) < 0
    assert t == pytest.approx(np.log(0.93), abs=0.025), grid


def test_the_masks_read_the_height_where_the_landmarks_misread_it(walk):
    """core/actor/height_by_masks.py: on synthetic masks of an actor whose segments are all 5 % longer, the scan
    from the rig puts the height within 1.5 % of the actor's and, the two more than 3 % apart, takes it; on masks
    of the rig itself it stays within the gate and is not taken. taller keeps the head, hands and girth."""
    from markerless_mocap.core.actor.body_choice import mask_mismatch
    from markerless_mocap.core.actor.height_by_masks import height_by_masks, taller
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses = walk
    start = Proportions({k: 1.0 for k in ("spine", "neck", "shoulder_width", "hip_width", "upper_arm", "forearm",
                                          "thigh", "shin", "foot")}, 1.0)
    actor = taller(start, np.log(1.05))
    assert actor.overall == 1.0 and list(actor.factors.values()) == [pytest.approx(1.05)] * 9
    truth = segment_lengths(scaled_body(body, actor))["height"]
    cameras = [c.scaled(0.5) for c in read_calibration(scene_dir("walk"))]
    frames = np.arange(0, 60, 15)
    pushed = poses[frames] + np.random.default_rng(9).normal(0.0, 0.02, poses[frames].shape)
    proxy = make_proxy(body, 2000)
    for masks_of, expected, taken in ((actor, truth, True), (start, segment_lengths(body)["height"], False)):
        masks = _synthetic_masks(scaled_body(body, masks_of), cameras, poses[frames])
        found = height_by_masks(body, start, lambda bodies, masks=masks: mask_mismatch(
            body, proxy, cameras, masks, [(p, pushed) for p in bodies], backend="fast"))
        assert found["landmark_height_m"] == pytest.approx(segment_lengths(body)["height"])
        assert found["masks_height_m"] == pytest.approx(expected, rel=0.015), found["grid"]
        assert found["taken"] is taken, found


def test_a_line_search_refines_inside_the_grid_and_stops_at_its_end():
    """core/actor/mask_line_search.py on a known parabola: the vertex between grid points is found exactly; a cost
    still falling at the grid's end gives no move, and pinned_down says so (keys as saved in actor.json too)."""
    from markerless_mocap.core.actor.mask_line_search import pinned_down, search_line

    def costs(points):
        return [(p - 0.041) ** 2 for p in points]
    t, table = search_line(0.0, lambda start, t: start + t, costs, 0.03, 4)
    assert t == pytest.approx(0.041, abs=1e-9) and len(table) == 9 and pinned_down(table)
    t, table = search_line(0.0, lambda start, t: start + t, lambda points: [-p for p in points], 0.03, 4)
    assert t == 0.0 and not pinned_down(table) and not pinned_down({str(k): v for k, v in table.items()})
