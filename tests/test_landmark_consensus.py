"""Landmarks another person gave: set aside by the views' agreement in 3D, with no other actor known (a passer-by,
someone who was not given an armature)."""
import numpy as np
import pytest

pytest.importorskip("bpy")

from scene_helpers import mean_joint_error, walk_with_another_person  # noqa: E402

from markerless_mocap.core.evidence.keypoint_fit import pose_from_keypoints  # noqa: E402
from markerless_mocap.core.evidence.keypoints import KeypointTargets  # noqa: E402
from markerless_mocap.core.evidence.landmark_consensus import disagreeing_landmarks, set_aside_disagreeing  # noqa: E402
from markerless_mocap.core.evidence.learned import CROP_MARGIN  # noqa: E402


@pytest.fixture(scope="module")
def walk():
    return walk_with_another_person()


def _targets(uv, n_views, n_points):
    return KeypointTargets(uv, np.full((n_views, n_points), 0.95), np.full(n_views, 200.0 / CROP_MARGIN))


def test_another_persons_landmarks_in_one_view_do_not_move_the_fit(walk):
    """View 0 shows the other person's landmarks and view 1 one wrist of theirs: both set aside without knowing
    who the other person is, the fit equals the fit on the clean landmarks alone; kept, it moves."""
    body, cameras, rig, truth, predicted, points, theirs = walk
    uv = points(truth)
    uv[0] = theirs[0]
    wrist = int(np.nonzero(rig.landmarks == 15)[0][0])  # the left wrist's rig point
    uv[1, wrist] = theirs[1, wrist]
    targets = _targets(uv, len(cameras), len(rig.landmarks))
    clean = KeypointTargets(points(truth), targets.weight.copy(), targets.person_px)
    clean.weight[0] = 0.0
    clean.weight[1, wrist] = 0.0
    predicted_world = rig.world(body, predicted[None])[0]

    kept, aside, taken = set_aside_disagreeing(cameras, targets, rig.swap, predicted_world)
    assert taken.tolist() == [True] + [False] * (len(cameras) - 1)
    assert aside[1].tolist() == [k == wrist for k in range(len(rig.landmarks))]
    assert not aside[2:].any()
    assert np.array_equal(kept.weight, clean.weight)
    fit_kept = pose_from_keypoints(body, cameras, kept, rig, predicted.copy())[0]
    fit_clean = pose_from_keypoints(body, cameras, clean, rig, predicted.copy())[0]
    fit_all = pose_from_keypoints(body, cameras, targets, rig, predicted.copy())[0]
    assert mean_joint_error(body, fit_kept, fit_clean) < 1e-6
    assert mean_joint_error(body, fit_kept, truth) < 0.02
    assert mean_joint_error(body, fit_all, truth) > 2 * mean_joint_error(body, fit_kept, truth) + 0.01


def test_noisy_and_side_swapped_landmarks_of_the_actor_are_all_kept(walk):
    """A few pixels of noise and a view that took the person's left for the right are the actor's own."""
    body, cameras, rig, truth, predicted, points, _ = walk
    uv = points(truth) + np.random.default_rng(0).normal(0.0, 2.0, (len(cameras), len(rig.landmarks), 2))
    uv[2] = uv[2, rig.swap]
    weight = np.full((len(cameras), len(rig.landmarks)), 0.95)
    aside = disagreeing_landmarks(cameras, uv, weight, np.full(len(cameras), 200.0 / CROP_MARGIN), rig.swap,
                                  rig.world(body, predicted[None])[0])
    assert not aside.any()


def test_two_views_against_two_the_prediction_decides(walk):
    """Two of four views show the other person: two against two, the side nearer this actor's predicted pose wins."""
    body, cameras, rig, truth, predicted, points, theirs = walk
    assert len(cameras) == 4
    uv = points(truth)
    uv[[0, 3]] = theirs[[0, 3]]
    targets = _targets(uv, 4, len(rig.landmarks))
    _, aside, taken = set_aside_disagreeing(cameras, targets, rig.swap, rig.world(body, predicted[None])[0])
    assert taken.tolist() == [True, False, False, True]
    assert not aside[[1, 2]].any()
