"""Fast arms through smoothing (core/tracking/fast_arms.py): the weight's speeds, and on the walk's rig a hand flung
within three frames, which the plain low-pass cuts short and the smoothing with fast arms follows, while the still
arm and the slow frames are smoothed exactly as before."""
import numpy as np
import pytest

from markerless_mocap.core.tracking.fast_arms import FAST_ARM_FROM, FAST_ARM_TO, arms, fast_weights
from markerless_mocap.core.tracking.smoothing import smooth_poses

FPS = 30.0


def _path(step_speeds):
    """Wrist positions about the shoulder (F, 3) stepping along x at the given signed speeds (m/s)."""
    path = np.zeros((len(step_speeds) + 1, 3))
    path[1:, 0] = np.cumsum(step_speeds) / FPS
    return path


def test_the_weight_grows_from_the_first_speed_to_the_second():
    middle = (FAST_ARM_FROM + FAST_ARM_TO) / 2
    for speed, weight in ((FAST_ARM_FROM - 0.5, 0.0), (middle, 0.5), (FAST_ARM_TO + 1.0, 1.0)):
        np.testing.assert_allclose(fast_weights(_path([speed] * 5), np.arange(6), FPS), weight)


def test_an_arm_jumping_back_and_forth_is_not_fast_and_a_gap_is_no_step():
    jumping = _path([3 * FAST_ARM_TO, -3 * FAST_ARM_TO] * 4)  # 0.5 m a frame, back and forth
    w = fast_weights(jumping, np.arange(9), FPS)
    np.testing.assert_allclose(w[1:-1], 0.0)  # between its neighbours it has not moved
    path = _path([2 * FAST_ARM_TO] * 5)
    # frame 3 -> 10 is a gap: each run's frames are judged within the run only, its end frames on one step
    np.testing.assert_allclose(fast_weights(path, np.array([0, 1, 2, 3, 10, 11]), FPS), 1.0)
    alone = fast_weights(path, np.array([0, 1, 2, 3, 10, 20]), FPS)  # frames 10 and 20 stand alone: no speed
    np.testing.assert_allclose(alone, [1.0, 1.0, 1.0, 1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def fling():
    """(body, true poses, solved poses: the truth with jitter) of 60 frames on the walk's rig: the right arm
    raised by 150 degrees within three frames at frame 30 (the wrist at about 11 m/s), the left arm still."""
    bpy = pytest.importorskip("bpy")
    from scene_helpers import load_scene_body

    body, _ = load_scene_body(bpy, "walk")
    names = body.dof_names
    truth = np.repeat(body.default_pose()[None], 60, axis=0)
    raise_ = np.clip((np.arange(60) - 29) / 3.0, 0.0, 1.0)
    truth[:, names.index("r_shoulder.flex")] = np.clip(np.radians(150) * raise_, body.lower[names.index(
        "r_shoulder.flex")], body.upper[names.index("r_shoulder.flex")])
    jitter = np.random.default_rng(3).normal(0.0, 0.01, truth.shape)
    jitter[:, body.translation_dofs] *= 0.3  # metres, not radians
    solved = body.clamp(truth + jitter)
    return body, truth, solved


def _wrist(body, poses, side):
    (_, _, wrist, _), = [a for a in arms(body) if a[0] == side]
    return body.joint_positions(poses)[:, wrist]


def test_a_flung_hand_is_followed_where_the_plain_filter_cuts_its_path_short(fling):
    body, truth, solved = fling
    frames = np.arange(len(truth))
    plain = smooth_poses(body, solved, frames, FPS, fast_arms=False)
    fast = smooth_poses(body, solved, frames, FPS)
    true_wrist = _wrist(body, truth, "r")
    speed = np.linalg.norm(np.diff(true_wrist, axis=0), axis=-1).max() * FPS
    assert speed > FAST_ARM_TO  # the fling is fast enough to be kept
    err_plain = np.linalg.norm(_wrist(body, plain, "r") - true_wrist, axis=-1)
    err_fast = np.linalg.norm(_wrist(body, fast, "r") - true_wrist, axis=-1)
    window = slice(27, 36)
    assert err_plain[window].max() > 0.06  # the plain low-pass cuts the fling's corner by centimetres
    assert err_fast[window].mean() < 0.6 * err_plain[window].mean()  # measured: 14 mm against 27
    assert err_fast.mean() < err_plain.mean()
    # the still left arm, the trunk and the legs, and the slow frames, are smoothed exactly as before
    right = arms(body)[[a[0] for a in arms(body)].index("r")][3]
    others = np.setdiff1d(np.arange(body.n_dof), right)
    np.testing.assert_allclose(fast[:, others], plain[:, others], atol=1e-12)
    np.testing.assert_allclose(fast[:20], plain[:20], atol=1e-12)
    np.testing.assert_allclose(fast[45:], plain[45:], atol=1e-12)


def test_a_rig_without_arm_roles_is_smoothed_as_before(fling):
    body, _, solved = fling
    from types import SimpleNamespace

    bare = SimpleNamespace(root_rotation_dofs=body.root_rotation_dofs, lower=body.lower, upper=body.upper)
    frames = np.arange(len(solved))
    np.testing.assert_allclose(smooth_poses(bare, solved, frames, FPS),
                               smooth_poses(body, solved, frames, FPS, fast_arms=False), atol=1e-12)
