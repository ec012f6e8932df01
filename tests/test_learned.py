"""Learned evidence: crop geometry, the BlazePose wrapper on a rendered frame, the keypoint term and the
first frame from keypoints."""

import cv2
import numpy as np
import pytest

from scene_helpers import ground_truth_poses, scene_dir

from markerless_mocap.core.evidence.learned import (INPUT_SIZE, CropBox, LandmarkModel, LearnedModelError, ViewEvidence,
                                                    crop_around, crop_image, locate, mask_at_size, mask_to_image)

LIMB_LANDMARKS = {11: "LeftArm", 12: "RightArm", 13: "LeftForeArm", 14: "RightForeArm", 15: "LeftHand",
                  16: "RightHand", 23: "LeftUpLeg", 24: "RightUpLeg", 25: "LeftLeg", 26: "RightLeg",
                  27: "LeftFoot", 28: "RightFoot"}


# ------------------------------------------------------------------------------------------ crop geometry
def test_crop_round_trip_and_pixel_mapping():
    box = CropBox(cx=301.3, cy=188.9, size=173.0)
    pts = np.array([[250.0, 120.0], [301.3, 188.9], [380.5, 270.25]])
    assert np.allclose(box.to_image(box.to_crop(pts)), pts, atol=1e-9)
    assert np.allclose(box.to_crop([[box.cx, box.cy]]), [[INPUT_SIZE / 2, INPUT_SIZE / 2]])
    # A bright square centred on an image point lands centred on that point's crop coordinates.
    img = np.zeros((480, 640, 3), np.uint8)
    cv2.rectangle(img, (276, 146), (284, 154), (255, 255, 255), -1)  # centre (280.5, 150.5) in pixel-centre terms
    crop = crop_image(img, box)[..., 0]
    ys, xs = np.nonzero(crop > 0.5)
    centre = np.array([xs.mean() + 0.5, ys.mean() + 0.5])  # crop pixel centres, edge convention
    assert np.allclose(centre, box.to_crop([[280.5, 150.5]])[0], atol=0.75)


def test_mask_outside_the_crop_is_unknown():
    box = CropBox(cx=100.0, cy=80.0, size=64.0)
    prob = mask_to_image(np.ones((INPUT_SIZE, INPUT_SIZE), np.float32), box, 320, 240)
    known = np.isfinite(prob)
    assert known[80, 100] and prob[80, 100] == pytest.approx(1.0)
    assert not known[80, 200] and not known[10, 10]
    assert abs(int(known.sum()) - 64 * 64) <= 2 * 64 + 4  # the square, up to its border pixels


def test_mask_sampled_at_a_feature_size_matches_the_full_resolution_path():
    """The tracker samples the crop's mask straight at its feature resolutions (mask_at); the reference is the
    full-resolution mask area-resampled. A blob in a crop partly outside an HD frame, at 0.1 and 0.23."""
    yy, xx = np.mgrid[0:INPUT_SIZE, 0:INPUT_SIZE]
    prob = 1.0 / (1.0 + np.exp(-(40.0 - np.hypot(xx - 140.0, (yy - 110.0) * 0.5)) / 3.0)).astype(np.float32)
    box = CropBox(cx=900.3, cy=1500.7, size=1100.0)  # reaches past the bottom of a 1080 x 1920 frame
    lazy = ViewEvidence(None, np.zeros((33, 2)), np.ones(33), 1.0, box, crop_prob=prob, image_size=(1080, 1920))
    reference = ViewEvidence(mask_to_image(prob, box, 1080, 1920), np.zeros((33, 2)), np.ones(33), 1.0, box)
    for scale in (0.1, 0.23):
        size = (int(round(1080 * scale)), int(round(1920 * scale)))
        fast, slow = lazy.mask_at(size), reference.mask_at(size)
        assert fast.shape == slow.shape == size[::-1]
        assert slow.sum() > 500 * scale and (fast ^ slow).sum() <= 0.02 * slow.sum() + 2  # only boundary pixels
        direct = mask_at_size(prob, box, (1080, 1920), size)
        assert direct.min() >= 0.0 and direct.max() <= 1.0
    assert np.array_equal(lazy.mask, reference.mask)  # the full-resolution mask made on demand is the same


def test_crop_around_is_a_square_with_margin():
    box = crop_around([[100, 50], [140, 250]], margin=1.5)
    assert (box.cx, box.cy) == (120.0, 150.0)
    assert box.size == pytest.approx(300.0)


def test_missing_model_file_names_the_fix(tmp_path):
    with pytest.raises(LearnedModelError, match="reinstall the extension"):
        LandmarkModel(tmp_path / "nope.tflite")


def test_an_unknown_landmark_model_names_the_ones_there_are():
    from markerless_mocap.core.evidence.learned import model_path

    with pytest.raises(LearnedModelError, match="not one of full, heavy"):
        model_path("huge")


def test_the_options_landmark_models_are_the_model_files():
    """The panel's and the command line's Landmark Model lists exactly the model files that ship, each with its
    offsets table; a model without one is refused."""
    from markerless_mocap.core.evidence.keypoints import OFFSETS_OF_MODEL, KeypointMapError, offsets_table
    from markerless_mocap.core.evidence.learned import LANDMARK_MODEL_FILES, model_path
    from markerless_mocap.core.tracking.options import OPTIONS

    assert OPTIONS["landmarks"].values == ("auto", *LANDMARK_MODEL_FILES)
    assert tuple(LANDMARK_MODEL_FILES) == tuple(OFFSETS_OF_MODEL)
    assert OPTIONS["landmarks"].default == "auto"  # the preset's: docs/defaults.md, "landmarks"
    for name in LANDMARK_MODEL_FILES:
        assert model_path(name).is_file()
    with pytest.raises(KeypointMapError, match="no offsets table"):
        offsets_table("lite")


# ------------------------------------------------------------------------------------------ the model on a frame
@pytest.fixture(scope="module")
def walk_frame():
    pytest.importorskip("bpy")
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.results.result_folder import load_joints

    capture = load_capture(scene_dir("walk"))
    names, _, positions = load_joints(scene_dir("walk") / "gt_joints.npz")
    return capture, list(names), positions


@pytest.mark.parametrize("model", ["full", "heavy"])
def test_model_finds_the_person_on_a_rendered_frame(walk_frame, model):
    """Crops from the true pose, walk frame 0, either landmark model: 12 limb landmarks within 12 px median of the
    projected true joints (measured 3.5-7.8 px per view with full, 3.7-8.5 with heavy), person masks IoU >= 0.85
    with the true masks (measured 0.89-0.95 with full; heavy's mask is looser on one view: 0.84-0.96, so 0.8)."""
    from markerless_mocap.core.evidence.learned import model_path

    capture, names, positions = walk_frame
    images = capture.frames.read(0)
    cams = capture.cameras
    boxes = [crop_around(cam.project(positions[0])) for cam in cams]
    evidence = locate(LandmarkModel(model_path(model)), [images[c.name] for c in cams], boxes)
    for cam, ev in zip(cams, evidence):
        assert ev.found and ev.presence > 0.9
        uv = cam.project(positions[0])
        errors = [np.linalg.norm(ev.keypoints[k] - uv[names.index(b)]) for k, b in LIMB_LANDMARKS.items()]
        truth = cv2.imread(str(scene_dir("walk") / "gt_masks" / cam.name / "0000.png"), cv2.IMREAD_GRAYSCALE) > 127
        iou = (truth & ev.mask).sum() / (truth | ev.mask).sum()
        print(f"{cam.name}: median landmark error {np.median(errors):.1f} px, mask IoU {iou:.3f}")
        assert np.median(errors) < 12.0
        assert iou >= (0.85 if model == "full" else 0.8)


def test_a_crop_without_the_person_is_found_again_or_given_up(walk_frame):
    capture, names, positions = walk_frame
    cam = capture.cameras[0]
    image = capture.frames.read(0)[cam.name]
    uv = cam.project(positions[0])
    far = CropBox(40.0, 40.0, 60.0)  # an empty corner of the room
    truth_box = crop_around(uv)
    fg = np.zeros(image.shape[:2], bool)
    x0, y0 = (truth_box.to_image([[40, 20]])[0]).astype(int)
    x1, y1 = (truth_box.to_image([[216, 236]])[0]).astype(int)
    fg[max(0, y0):y1, max(0, x0):x1] = True  # a person-shaped foreground blob where the person is
    model = LandmarkModel()
    lost = locate(model, [image], [far])[0]
    assert not lost.found and lost.box is None and np.isnan(lost.mask_prob).all()
    refound = locate(model, [image], [far], foreground=lambda i: fg)[0]
    assert refound.found
    assert np.median(np.linalg.norm(refound.keypoints[[11, 12, 23, 24]] - uv[[names.index(b) for b in
                                    ("LeftArm", "RightArm", "LeftUpLeg", "RightUpLeg")]], axis=1)) < 15


# ------------------------------------------------------------------------------------------ the keypoint term
@pytest.fixture(scope="module")
def walk_truth():
    pytest.importorskip("bpy")
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.keypoints import rig_keypoints

    body, frames, poses, _ = ground_truth_poses("walk")
    capture = load_capture(scene_dir("walk"))
    return body, poses, capture.cameras, rig_keypoints(body)


def synthetic_evidence(body, pose, cameras, rig_points, noise_px=0.0, seed=0):
    """ViewEvidence per camera with the landmarks at the projected rig points of `pose`."""
    rng = np.random.default_rng(seed)
    pts = rig_points.world(body, pose[None])[0]
    out = []
    for cam in cameras:
        kp = np.full((33, 2), np.nan)
        vis = np.zeros(33)
        kp[rig_points.landmarks] = cam.project(pts) + rng.normal(0, noise_px, (len(pts), 2))
        vis[rig_points.landmarks] = 0.95
        out.append(ViewEvidence(np.zeros((cam.height, cam.width), np.float32), kp, vis, 1.0,
                                crop_around(cam.project(body.joint_positions(pose[None])[0]))))
    return out


def keypoint_term(body, cameras, evidence, poses):
    from markerless_mocap.core.evidence.learned import CROP_MARGIN
    from markerless_mocap.core.evidence.keypoints import KeypointTargets, keypoint_energy, rig_keypoints

    rig = rig_keypoints(body)
    targets = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    pts = rig.world(body, np.atleast_2d(poses))
    P, K = pts.shape[:2]
    projected = np.stack([c.project(pts.reshape(-1, 3)).reshape(P, K, 2) for c in cameras], axis=1)
    return keypoint_energy(projected, targets, rig.swap)


def test_rig_points_sit_at_the_joints_moved_by_the_landmark_offsets(walk_truth):
    """Each limb landmark's rig point is its joint moved by LANDMARK_OFFSETS in the bone's frame: in the
    rest pose by exactly the table's (outwards, forwards, up) x trunk, mirrored for the right side; posed,
    at the same distance from its joint (the bone carries it rigidly)."""
    from markerless_mocap.core.body.model import body_frame
    from markerless_mocap.core.evidence.keypoints import LANDMARK_OFFSETS

    body, poses, cameras, rig = walk_truth
    sk = body.skeleton
    frame = body_frame(sk, body.roles)
    trunk = np.linalg.norm(sk.rest[sk.index["Neck"], :3, 3] - sk.rest[sk.index["Hips"], :3, 3])
    heads = body.joint_positions(poses[:1])[0]
    posed = rig.world(body, poses[:1])[0]
    for lm, bone in LIMB_LANDMARKS.items():
        k = list(rig.landmarks).index(lm)
        outwards, forwards, up = LANDMARK_OFFSETS[lm if lm % 2 else lm - 1]
        side = 1 if lm % 2 else -1
        at_rest = rig.rest_points[k, :3] - sk.rest[sk.index[bone], :3, 3]
        np.testing.assert_allclose(at_rest @ np.stack([frame.left, frame.forward, frame.up]).T,
                                   trunk * np.array([side * outwards, forwards, up]), atol=1e-9)
        assert np.linalg.norm(posed[k] - heads[sk.index[bone]]) == pytest.approx(np.linalg.norm(at_rest), abs=1e-6)
    nose = posed[list(rig.landmarks).index(0)]
    assert nose[2] > heads[sk.index["Neck1"]][2]  # above the neck, on the face


def test_shoulder_and_hip_points_stay_on_the_trunk_when_the_limb_turns(walk_truth):
    """BlazePose's shoulder and hip landmarks lie on the trunk (acromion, pelvis): their rig points are carried
    by the clavicle and pelvis bones, so turning the upper arm or thigh moves the elbow and knee points and
    leaves the shoulder and hip points where they were."""
    body, poses, cameras, rig = walk_truth
    pose = poses[0].copy()
    turned = pose.copy()
    names = list(body.dof_names)
    for side in ("l", "r"):
        for role in ("shoulder", "hip"):
            for i, name in enumerate(names):
                if name.startswith(f"{side}_{role}"):
                    turned[i] += np.deg2rad(25.0)
    before, after = rig.world(body, np.stack([pose, turned]))
    moved = np.linalg.norm(after - before, axis=1)
    index = {int(lm): k for k, lm in enumerate(rig.landmarks)}
    for lm in (11, 12, 23, 24):  # shoulders, hips
        assert moved[index[lm]] < 1e-9, lm
    for lm in (13, 14, 25, 26):  # elbows, knees
        assert moved[index[lm]] > 0.05, lm


def test_keypoint_term_prefers_the_truth_to_perturbations(walk_truth):
    body, poses, cameras, rig = walk_truth
    truth = poses[20]
    evidence = synthetic_evidence(body, truth, cameras, rig, noise_px=3.0)
    rng = np.random.default_rng(5)
    scale = np.where(np.isin(np.arange(body.n_dof), body.translation_dofs), 0.05, np.deg2rad(10.0))
    perturbed = body.clamp(truth + rng.normal(0, 1, (300, body.n_dof)) * scale)
    e = keypoint_term(body, cameras, evidence, np.vstack([truth, perturbed]))
    assert 0 <= e[0] < 0.2  # 3 px of noise against a 10 px sigma: about 0.13
    assert (e[1:] > e[0]).mean() >= 0.97


def test_fast_keypoint_term_matches_the_numpy_reference(walk_truth):
    """core/evidence/keypoints_fast.py against keypoints.keypoint_energy_reference (1e-12): noisy landmarks with second
    guesses, a view with its sides swapped, a view without landmarks, poses near and far from the truth."""
    from markerless_mocap.core.evidence.learned import CROP_MARGIN, SWAP_ORDER
    from markerless_mocap.core.evidence.keypoints_fast import keypoint_energy as fast
    from markerless_mocap.core.evidence.keypoints import KEYPOINT_SIGMA, KeypointTargets, keypoint_energy_reference

    body, poses, cameras, rig = walk_truth
    rng = np.random.default_rng(8)
    evidence = synthetic_evidence(body, poses[20], cameras, rig, noise_px=4.0)
    evidence[1].keypoints = evidence[1].keypoints[SWAP_ORDER]
    for ev in evidence:
        ev.alternatives = np.concatenate([ev.keypoints[:, None] + rng.normal(0, 30, (33, 2, 2)),
                                          rng.uniform(0, 3, (33, 2, 1))], axis=2)
        ev.alternatives[rng.random((33, 2)) < 0.4] = np.nan  # landmarks without a second guess
    targets = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    scale = np.where(np.isin(np.arange(body.n_dof), body.translation_dofs), 0.1, np.deg2rad(20.0))
    trial = body.clamp(poses[20] + rng.normal(0, 1, (60, body.n_dof)) * scale)
    pts = rig.world(body, trial)
    projected = np.stack([c.project(pts.reshape(-1, 3)).reshape(pts.shape[:2] + (2,)) for c in cameras], axis=1)
    want = keypoint_energy_reference(projected, targets, rig.swap)
    assert np.ptp(want) > 0.1  # poses that the term tells apart
    wide = 4 * KEYPOINT_SIGMA
    np.testing.assert_allclose(fast(projected, targets, rig.swap, wide),
                               keypoint_energy_reference(projected, targets, rig.swap, wide), atol=1e-12)
    np.testing.assert_allclose(fast(projected, targets, rig.swap, KEYPOINT_SIGMA), want, atol=1e-12)
    targets.weight[2] = 0.0  # a view that found nobody
    np.testing.assert_allclose(fast(projected, targets, rig.swap, KEYPOINT_SIGMA),
                               keypoint_energy_reference(projected, targets, rig.swap), atol=1e-12)


def test_a_view_with_swapped_sides_does_not_pull_the_fit(walk_truth):
    from markerless_mocap.core.evidence.learned import SWAP_ORDER

    body, poses, cameras, rig = walk_truth
    truth = poses[20]
    clean = synthetic_evidence(body, truth, cameras, rig)
    swapped = synthetic_evidence(body, truth, cameras, rig)
    swapped[1].keypoints = swapped[1].keypoints[SWAP_ORDER]  # one view labels every side the other way
    # The truth costs the same with the swapped view, and stays the best of its perturbations.
    e_clean = keypoint_term(body, cameras, clean, truth[None])[0]
    e_swapped = keypoint_term(body, cameras, swapped, truth[None])[0]
    assert e_swapped == pytest.approx(e_clean, abs=1e-9)
    rng = np.random.default_rng(6)
    scale = np.where(np.isin(np.arange(body.n_dof), body.translation_dofs), 0.03, np.deg2rad(6.0))
    perturbed = body.clamp(truth + rng.normal(0, 1, (200, body.n_dof)) * scale)
    e = keypoint_term(body, cameras, swapped, np.vstack([truth, perturbed]))
    assert (e[1:] > e[0]).all()


def test_views_without_landmarks_are_left_out(walk_truth):
    body, poses, cameras, rig = walk_truth
    truth = poses[20]
    evidence = synthetic_evidence(body, truth, cameras, rig, noise_px=2.0)
    wrong = synthetic_evidence(body, poses[40], cameras, rig)
    with_lost_view = evidence[:3] + [ViewEvidence.empty(cameras[3].width, cameras[3].height)]
    three = keypoint_term(body, cameras[:3], evidence[:3], truth[None])[0]
    assert keypoint_term(body, cameras, with_lost_view, truth[None])[0] == pytest.approx(three)
    assert keypoint_term(body, cameras, wrong, truth[None])[0] > 5 * three


def test_first_frame_from_keypoints_recovers_the_pose(walk_truth):
    """Landmarks with 3 px noise, one view's sides swapped, the start 15 cm and 20 degrees off in a neutral
    posture: the fitted pose's joints within 40 mm of the truth on average (measured about 20 mm)."""
    from markerless_mocap.core.evidence.learned import CROP_MARGIN, SWAP_ORDER
    from markerless_mocap.core.evidence.keypoint_fit import pose_from_keypoints
    from markerless_mocap.core.evidence.keypoints import KeypointTargets
    from markerless_mocap.core.body.rotations import matrix_to_rotvec, rotvec_to_matrix

    body, poses, cameras, rig = walk_truth
    truth = poses[30]
    evidence = synthetic_evidence(body, truth, cameras, rig, noise_px=3.0, seed=2)
    evidence[2].keypoints = evidence[2].keypoints[SWAP_ORDER]
    targets = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    start = body.default_pose()
    start[body.translation_dofs] = truth[body.translation_dofs] + [0.15, -0.05, 0.0]
    yaw = rotvec_to_matrix(np.array([0.0, 0.0, np.deg2rad(20.0)]))
    start[body.root_rotation_dofs] = matrix_to_rotvec(yaw @ rotvec_to_matrix(truth[body.root_rotation_dofs]))
    pose, n_points, rms = pose_from_keypoints(body, cameras, targets, rig, start)
    error = np.linalg.norm(body.joint_positions(pose[None])[0] - body.joint_positions(truth[None])[0], axis=1)
    print(f"{n_points} points triangulated, rms {1000 * rms:.1f} mm, mean joint error {1000 * error.mean():.1f} mm")
    assert n_points == len(rig.landmarks)
    assert error.mean() < 0.04


def _triangulate_one_by_one(cameras, uv, weight, min_weight):
    """Reference DLT: each point on its own, only the rows of the views whose weight passes."""
    X, ok = np.full((uv.shape[1], 3), np.nan), np.zeros(uv.shape[1], bool)
    for k in range(uv.shape[1]):
        rows = []
        for c, cam in enumerate(cameras):
            if weight[c, k] >= min_weight:
                (u, v), P = cam.undistort_points(uv[c, k]), cam.projection_matrix
                rows += [weight[c, k] * (u * P[2] - P[0]), weight[c, k] * (v * P[2] - P[1])]
        if len(rows) >= 4:
            h = np.linalg.svd(np.array(rows))[2][-1]
            X[k], ok[k] = h[:3] / h[3], True
    return X, ok


def _swaps_by_trying_each(cameras, uv, weight, swap, min_weight):
    """Reference swap resolution: every minority of views flipped in turn, the pair triangulated one point at
    a time, the flip set with the smallest reprojection error kept (the first of equals)."""
    uv, weight = uv.copy(), weight.copy()
    for a, b in [(a, int(b)) for a, b in enumerate(swap) if a < b]:
        views = [c for c in range(len(cameras)) if min(weight[c, a], weight[c, b]) >= min_weight]
        if len(views) < 3:
            continue
        best, best_flip = np.inf, []
        for mask in range(1 << len(views)):
            flip = [views[i] for i in range(len(views)) if mask >> i & 1]
            if 2 * len(flip) >= len(views):
                continue
            tu, tw = uv[:, [a, b]].copy(), weight[:, [a, b]].copy()
            tu[flip], tw[flip] = tu[flip][:, ::-1], tw[flip][:, ::-1]
            X, ok = _triangulate_one_by_one(cameras, tu, tw, min_weight)
            if ok.all():
                err = sum(np.linalg.norm(cameras[c].project(X[i]) - tu[c, i]) for c in views for i in (0, 1))
                if err < best:
                    best, best_flip = err, flip
        for c in best_flip:
            uv[c, [a, b]], weight[c, [a, b]] = uv[c, [b, a]], weight[c, [b, a]]
    return uv, weight


def test_batched_triangulation_and_swaps_match_the_one_point_at_a_time_reference(walk_truth):
    """keypoint_fit's batched DLT and swap search against the plain loops above, on landmarks with noise,
    dropped detections and whole views whose sides are swapped: the same swaps, the same points (1e-9 m)."""
    from markerless_mocap.core.evidence.keypoint_fit import MIN_WEIGHT, resolve_swaps, triangulate

    body, poses, cameras, rig = walk_truth
    rng = np.random.default_rng(3)
    flipped_views = 0
    for trial in range(12):
        points = rig.world(body, poses[5 * trial][None])[0]
        uv = np.stack([cam.project(points) for cam in cameras]) + rng.normal(0, 4.0, (len(cameras), len(points), 2))
        shape = (len(cameras), len(points))
        weight = np.where(rng.random(shape) < 0.15, 0.0, rng.uniform(0.3, 1.0, shape))
        for c in range(len(cameras)):
            if rng.random() < 0.3:
                uv[c], weight[c] = uv[c, rig.swap], weight[c, rig.swap]
                flipped_views += 1
        got_uv, got_w = resolve_swaps(cameras, uv, weight, rig.swap)
        want_uv, want_w = _swaps_by_trying_each(cameras, uv, weight, rig.swap, MIN_WEIGHT)
        np.testing.assert_array_equal(got_uv, want_uv)
        np.testing.assert_array_equal(got_w, want_w)
        X, ok = triangulate(cameras, got_uv, got_w)
        X_ref, ok_ref = _triangulate_one_by_one(cameras, got_uv, got_w, MIN_WEIGHT)
        np.testing.assert_array_equal(ok, ok_ref)
        np.testing.assert_allclose(X[ok], X_ref[ok], atol=1e-9)
    assert flipped_views >= 5


def test_icp_keypoint_gradient_matches_finite_differences(walk_truth):
    """The analytic keypoint block of ICP's normal equations: its gradient equals the numerical one of
    the keypoint cost (a Huber threshold wide enough that every residual is in its quadratic zone)."""
    from markerless_mocap.core.evidence.learned import CROP_MARGIN
    from markerless_mocap.core.evidence.keypoints import KeypointTargets
    from markerless_mocap.core.optimizers import PoseSpace
    from markerless_mocap.core.optimizers.icp import IcpProblem, IcpSettings, IcpSolver
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses, cameras, rig = walk_truth
    truth = poses[20]
    evidence = synthetic_evidence(body, truth, cameras, rig, noise_px=1.0, seed=3)
    targets = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    space = PoseSpace.with_default_scale(body.lower, body.upper, body.dof_names,
                                         np.isin(np.arange(body.n_dof), body.translation_dofs))
    sils = [np.zeros((c.height, c.width), bool) for c in cameras]
    problem = IcpProblem(body=body, proxy=make_proxy(body), cameras=cameras, silhouettes=sils,
                         keypoints=targets, rig_points=rig)
    solver = IcpSolver(problem, space, IcpSettings(keypoint_huber=50.0))
    x = truth.copy()
    assignment = solver._keypoint_assignment(x)
    _, g, cost = solver._keypoint_normal_equations(x, assignment)
    assert cost == pytest.approx(solver._keypoint_cost(x, assignment))
    joints = np.setdiff1d(np.arange(body.n_dof), body.root_rotation_dofs)  # the root rotation is a left increment
    h = 1e-6
    numeric = np.array([(solver._keypoint_cost(x + h * np.eye(body.n_dof)[i], assignment)
                         - solver._keypoint_cost(x - h * np.eye(body.n_dof)[i], assignment)) / (2 * h)
                        for i in joints])
    assert np.allclose(g[joints], numeric, rtol=1e-3, atol=1e-3 * np.abs(numeric).max())


def test_energy_resolution_follows_the_person_not_the_footage(walk_truth):
    """The walk keeps the 0.5 its figures were measured at; the same views filmed at 3x the resolution get a
    third of it, so the person spans the same number of energy pixels."""
    from markerless_mocap.core.energy.likelihood import ENERGY_PERSON_PX, energy_scale_for

    body, poses, cameras, _ = walk_truth
    assert energy_scale_for(body, cameras, poses[0]) == 0.5
    big = [c.scaled(3.0) for c in cameras]
    heights = [np.ptp(c.project(body.joint_positions(poses[:1])[0])[:, 1]) for c in big]
    scale = energy_scale_for(body, big, poses[0])
    assert scale == pytest.approx(ENERGY_PERSON_PX / np.median(heights))
    assert 0.1 < scale < 0.25


@pytest.mark.parametrize("model", [None, "full"])
def test_track_without_the_model_file_says_so_and_how_to_fix_it(tmp_path, monkeypatch, capsys, model):
    """The default model's file missing, or the one --landmarks asks for: a message naming it and the fix."""
    pytest.importorskip("bpy")
    from markerless_mocap.core.evidence import learned
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.operators.cli import main

    monkeypatch.setattr(learned, "MODEL_PATH", tmp_path / "missing.tflite")
    monkeypatch.setattr(learned, "MODELS_FOLDER", tmp_path)
    chosen = [] if model is None else ["--landmarks", model]
    code = main(["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(scene_dir("walk")),
                 "--out", str(tmp_path / "out"), "--frames", "0-1", "--likelihood", "lsilh+edge+kp", *chosen])
    err = capsys.readouterr().err
    assert code == 2
    assert "landmark model" in err and "reinstall the extension" in err and "Traceback" not in err
    assert learned.model_path(model or TrackingSettings().landmarks).name in err


def test_agreement_figures_of_a_model_on_and_off_the_person(walk_truth):
    """Coverage, IoU and keypoint distance: 1, 1 and 0 px for evidence made from the model itself; a model
    30 cm to the side of that person loses coverage and is tens of pixels from the landmarks."""
    from markerless_mocap.core.evidence.agreement import view_agreement
    from markerless_mocap.core.render.model_mask import model_mask
    from markerless_mocap.core.results.overlay import contact_sheet
    from markerless_mocap.core.body.proxy import make_proxy

    body, poses, cameras, rig = walk_truth
    proxy = make_proxy(body)
    truth = poses[20]
    cam = cameras[0]
    evidence = synthetic_evidence(body, truth, [cam], rig)[0]
    vertices = proxy.deform(body, truth[None])[0]
    evidence.mask_prob = model_mask(cam, vertices, proxy.faces).astype(np.float32)
    on = view_agreement(cam, evidence, vertices, proxy.faces, cam.project(rig.world(body, truth[None])[0]), rig)
    assert (on.coverage, on.iou, on.keypoint_px) == (1.0, 1.0, pytest.approx(0.0, abs=1e-6))
    moved = truth.copy()
    moved[body.translation_dofs[0]] += 0.3
    v_off = proxy.deform(body, moved[None])[0]
    off = view_agreement(cam, evidence, v_off, proxy.faces, cam.project(rig.world(body, moved[None])[0]), rig)
    assert off.coverage < 0.6 and off.keypoint_px > 20
    sheet = contact_sheet([[np.zeros((480, 640, 3), np.uint8)] * 4] * 2, cell_height=120, label_rows=["a", "b"])
    assert sheet.shape == (240, 4 * 160, 3)


def test_triangulation_baseline_of_exact_landmarks_is_exact(walk_truth, tmp_path):
    """keypoints.npz holding the true joints' projections (one view's sides swapped) triangulates back onto
    the truth: the baseline's error is the landmarks' own, not the code's."""
    from markerless_mocap.core.results.evaluation import TRIANGULATION_JOINTS, triangulation_errors
    from markerless_mocap.core.evidence.learned import SWAP_ORDER
    from markerless_mocap.core.results.result_folder import load_joints

    body, poses, cameras, rig = walk_truth
    truth = scene_dir("walk") / "gt_joints.npz"
    names, frames, positions = load_joints(truth)
    bones = {"l_shoulder": "LeftArm", "r_shoulder": "RightArm", "l_elbow": "LeftForeArm",
             "r_elbow": "RightForeArm", "l_wrist": "LeftHand", "r_wrist": "RightHand", "l_hip": "LeftUpLeg",
             "r_hip": "RightUpLeg", "l_knee": "LeftLeg", "r_knee": "RightLeg", "l_ankle": "LeftFoot",
             "r_ankle": "RightFoot"}
    use = frames[:5]
    uv = np.zeros((len(use), len(cameras), 33, 2))
    vis = np.zeros((len(use), len(cameras), 33))
    for i, f in enumerate(use):
        for c, cam in enumerate(cameras):
            for joint, lm in TRIANGULATION_JOINTS.items():
                uv[i, c, lm] = cam.project(positions[f, names.index(bones[joint])])
                vis[i, c, lm] = 0.9
        uv[i, 2] = uv[i, 2][SWAP_ORDER]
    np.savez(tmp_path / "keypoints.npz", frames=use, uv=uv, visibility=vis)
    got_frames, errors, joints = triangulation_errors(tmp_path / "keypoints.npz", cameras, truth)
    assert list(got_frames) == list(use) and joints == list(TRIANGULATION_JOINTS)
    assert np.nanmax(errors) < 1e-6


# ------------------------------------------------------------------------------------------ heatmap second guesses
def _blob(cx, cy, peak, size=64, width=1.5):
    """A heatmap of logits with one Gaussian bump at cell coordinates (cx, cy) (cell centres at i + 0.5)."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    return peak - 20.0 * (1 - np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2)))


def test_heatmap_alternatives_find_the_runner_up_peak():
    from markerless_mocap.core.evidence.learned import heatmap_alternatives

    heat = np.full((3, 64, 64), -20.0, np.float32)
    heat[0] = np.maximum(_blob(20.5, 30.5, 1.0), _blob(44.5, 12.5, 0.2))   # runner-up 0.8 logits down
    heat[1] = np.maximum(_blob(20.5, 30.5, 1.0), _blob(44.2, 12.8, 0.5))   # runner-up between cells
    heat[2] = np.maximum(_blob(20.5, 30.5, 1.0), _blob(50.5, 50.5, -4.0))  # runner-up 5 logits down
    regressed = np.array([[20.5 * 4, 30.5 * 4]] * 3)                        # crop pixels: 4 per cell
    alt = heatmap_alternatives(heat, regressed)
    assert alt.shape == (3, 2, 3)
    np.testing.assert_allclose(alt[0, 0], [44.5 * 4, 12.5 * 4, 0.8], atol=1e-4)
    np.testing.assert_allclose(alt[1, 0, :2], [44.2 * 4, 12.8 * 4], atol=0.5)  # refined within the cell
    assert np.isnan(alt[0, 1]).all() and np.isnan(alt[1, 1]).all() and np.isnan(alt[2]).all()


def _alternatives_one_landmark_at_a_time(heat, regressed, n, max_gap, min_distance):
    """Reference second guesses: each heatmap's 3 x 3 local maxima near its top, refined by a parabola per
    axis, away from the regressed point, the strongest n."""
    out = np.full((len(heat), n, 3), np.nan)
    cell = 256 / heat.shape[-1]
    for lm, h in enumerate(heat):
        peaks = np.argwhere((h == cv2.dilate(h, np.ones((3, 3), np.float32))) & (h >= h.max() - max_gap))
        found = []
        for r, c in peaks:
            def step(lo, mid, hi):
                curve = lo - 2 * mid + hi
                return float(np.clip(0.5 * (lo - hi) / curve, -0.5, 0.5)) if curve < 0 else 0.0
            up, down = h[max(r - 1, 0), c], h[min(r + 1, 63), c]
            left, right = h[r, max(c - 1, 0)], h[r, min(c + 1, 63)]
            uv = cell * np.array([c + 0.5 + step(left, h[r, c], right), r + 0.5 + step(up, h[r, c], down)])
            if np.linalg.norm(uv - regressed[lm]) >= min_distance:
                found.append((h.max() - h[r, c], uv))
        for i, (gap, uv) in enumerate(sorted(found, key=lambda f: f[0])[:n]):
            out[lm, i] = [uv[0], uv[1], gap]
    return out


def test_heatmap_alternatives_match_the_one_landmark_at_a_time_reference():
    """The all-landmarks-at-once second guesses against the plain loop above, on smooth random heatmaps with
    many peaks near the top (equal to 1e-6 crop pixels and logits)."""
    from markerless_mocap.core.evidence.learned import (ALTERNATIVE_MAX_GAP, ALTERNATIVE_MIN_DISTANCE, ALTERNATIVES,
                                                        heatmap_alternatives)

    rng = np.random.default_rng(4)
    found = 0
    for _ in range(20):
        noise = rng.normal(0, 1, (33, 64, 64)).astype(np.float32)
        heat = np.stack([cv2.GaussianBlur(h, (0, 0), 3) * 20 for h in noise])
        regressed = rng.uniform(0, 256, (33, 2))
        got = heatmap_alternatives(heat, regressed)
        want = _alternatives_one_landmark_at_a_time(heat, regressed, ALTERNATIVES, ALTERNATIVE_MAX_GAP,
                                                    ALTERNATIVE_MIN_DISTANCE)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)], atol=1e-6)
        found += int(np.isfinite(got[..., 2]).sum())
    assert found > 50  # the heatmaps do have second guesses to compare


def test_a_pose_on_a_second_guess_costs_little_more_than_on_the_landmark(walk_truth):
    """The left wrist's landmark regressed 60 px off (onto the other side of the body) in one view, with
    the true place as the heatmap's runner-up 0.4 logits down: the truth costs that view 0.1 more
    (ALTERNATIVE_COST_PER_LOGIT x 0.4), not an outlier's ~1, and ICP compares the wrist with the second
    guess where the pose puts it there."""
    from markerless_mocap.core.evidence.learned import CROP_MARGIN
    from markerless_mocap.core.evidence.keypoints import (ALTERNATIVE_COST_PER_LOGIT, KeypointTargets, chosen_targets,
                                                          keypoint_energy)

    body, poses, cameras, rig = walk_truth
    truth = poses[20]
    evidence = synthetic_evidence(body, truth, cameras, rig)
    wrist = list(rig.landmarks).index(15)
    true_uv = evidence[1].keypoints[15].copy()
    evidence[1].keypoints[15] = true_uv + [60.0, 0.0]
    pts = rig.world(body, truth[None])
    projected = np.stack([c.project(pts.reshape(-1, 3)).reshape(1, -1, 2) for c in cameras], axis=1)
    without = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    for ev in evidence:
        ev.alternatives = np.full((33, 2, 3), np.nan)
    evidence[1].alternatives[15, 0] = [*true_uv, 0.4]
    with_alt = KeypointTargets.from_evidence(evidence, rig, CROP_MARGIN)
    w = with_alt.weight[1]
    e_without = keypoint_energy(projected, without, rig.swap)[0]
    e_with = keypoint_energy(projected, with_alt, rig.swap)[0]
    view_share = w[wrist] / w.sum() / len(cameras)  # the wrist's share of the 4-view mean
    assert e_with == pytest.approx(view_share * ALTERNATIVE_COST_PER_LOGIT * 0.4, rel=1e-6)
    assert e_without > view_share * 0.9  # the off landmark: nearly an outlier's full cost
    chosen, _ = chosen_targets(projected[0], with_alt, rig.swap)
    np.testing.assert_allclose(chosen[1, wrist], true_uv)
    chosen, _ = chosen_targets(projected[0], without, rig.swap)
    np.testing.assert_allclose(chosen[1, wrist], true_uv + [60.0, 0.0])


@pytest.mark.parametrize("model", ["full", "heavy"])
def test_landmark_offsets_table_is_what_the_measuring_tool_finds(model):
    """Each landmark model's offsets table (LANDMARK_OFFSETS, HEAVY_LANDMARK_OFFSETS) against
    tools/landmark_offsets.py --raw --model on walk and playground (every 4th frame here, every 2nd or 3rd for the
    table): within 0.01 trunk (5 mm) per component. The two models place the elbows, knees and ankles 0.02-0.04
    trunk apart, so a table fits its own model only."""
    pytest.importorskip("bpy")

    from markerless_mocap.core.evidence.keypoints import offsets_table

    from tool_helpers import load_tool

    tool = load_tool("landmark_offsets")
    arrays = []
    for name in ("walk", "playground"):
        landmarks, result = tool.measure(scene_dir(name), 4, raw=True, model=model)
        arrays.append(result["own"])
    table = tool.medians(landmarks, np.concatenate(arrays))
    for lm, expected in offsets_table(model).items():
        np.testing.assert_allclose(table[lm][0], expected, atol=0.01, err_msg=f"landmark {lm}")
    other = offsets_table("heavy" if model == "full" else "full")
    assert max(np.abs(np.subtract(table[lm][0], other[lm])).max() for lm in other) > 0.02



def test_triangulation_takes_a_landmark_not_found_in_a_view_as_missing(walk_truth):
    """A view whose landmark has no pixels (NaN: not found there) leaves the triangulation as it is without that
    view, whatever weight came with it; before, 0 x NaN poisoned the whole batch (SVD did not converge)."""
    from markerless_mocap.core.evidence.keypoint_fit import triangulate

    _, _, cameras, _ = walk_truth
    points = np.array([[0.1, 0.2, 1.0], [-0.3, 0.1, 1.4]])
    uv = np.stack([cam.project(points) for cam in cameras])           # (C,2,2)
    weight = np.full(uv.shape[:2], 0.9)
    clean, ok_clean = triangulate(cameras[1:], uv[1:], weight[1:])
    for w0 in (0.0, 0.9):
        lost = uv.copy()
        lost[0, 0] = np.nan
        w = weight.copy()
        w[0, 0] = w0
        X, ok = triangulate(cameras, lost, w)
        assert ok.all() and np.isfinite(X).all()
        np.testing.assert_allclose(X[0], clean[0], atol=1e-9)
        np.testing.assert_allclose(X, points, atol=1e-6)
