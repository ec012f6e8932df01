"""Evaluation: 3D joint error, PCK and the command's output on constructed results with known errors."""
import json

import numpy as np
import pytest

from markerless_mocap.core.results.evaluation import EVAL_JOINTS, EvaluationError, joint_errors, summarise
from markerless_mocap.core.results.result_folder import load_joints
from markerless_mocap.operators.cli import main

NAMES = ["Hips", "LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg", "LeftFoot", "RightFoot", "LeftArm", "RightArm",
         "LeftForeArm", "RightForeArm", "LeftHand", "RightHand", "Neck", "Head", "LeftToeBase"]


def write_joints(path, positions, frames, names=NAMES):
    np.savez(path, names=np.array(names), frames=np.asarray(frames), positions=np.asarray(positions))


@pytest.fixture
def truth_and_result(tmp_path):
    rng = np.random.default_rng(0)
    F, J = 10, len(NAMES)
    truth = rng.normal(0, 0.5, (F, J, 3))
    offsets = np.zeros((F, J, 3))
    offsets[:, :, 0] = 0.02  # 20 mm on every joint ...
    offsets[5, :, 0] = 0.08  # ... except frame 5: 80 mm
    write_joints(tmp_path / "gt.npz", truth, np.arange(F))
    (tmp_path / "result").mkdir()
    # The result lists its bones in another order and misses frame 0: matching is by name and frame.
    perm = rng.permutation(J)
    write_joints(tmp_path / "result" / "joints.npz", (truth + offsets)[1:, perm], np.arange(1, F),
                 [NAMES[i] for i in perm])
    return tmp_path


def test_errors_are_matched_by_name_and_frame(truth_and_result):
    frames, err = joint_errors(truth_and_result / "result" / "joints.npz", truth_and_result / "gt.npz")
    assert list(frames) == list(range(1, 10))
    assert err.shape == (9, len(EVAL_JOINTS))  # the toe is not an evaluation joint
    s = summarise(frames, err)
    expected = np.array([20.0] * 4 + [80.0] + [20.0] * 4)
    assert s.mean_mm == pytest.approx(expected.mean())
    assert s.std_mm == pytest.approx(expected.std())
    assert s.max_mm == pytest.approx(80.0)
    assert s.pck50 == pytest.approx(8 / 9)
    assert s.pck100 == pytest.approx(1.0)


def test_evaluate_command_prints_json_and_plot(truth_and_result, capsys):
    code = main(["evaluate", "--result", str(truth_and_result / "result"), "--truth", str(truth_and_result / "gt.npz")])
    assert code == 0
    out = capsys.readouterr().out.strip().splitlines()
    figures = json.loads(out[-1])
    assert figures["mean_mm"] == pytest.approx(80 / 9 + 160 / 9)
    assert "raw_mean_mm" not in figures
    assert (truth_and_result / "result" / "error_per_frame.png").stat().st_size > 1000


def test_evaluate_also_scores_the_solved_poses_of_a_smoothed_take(truth_and_result, capsys):
    result = truth_and_result / "result"
    names, frames, positions = load_joints(result / "joints.npz")
    write_joints(result / "joints_raw.npz", positions + np.array([0.03, 0.0, 0.0]), frames, names)
    assert main(["evaluate", "--result", str(result), "--truth", str(truth_and_result / "gt.npz")]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    figures = json.loads(out[-1])
    assert figures["mean_mm"] == pytest.approx(80 / 9 + 160 / 9)  # joints.npz: the take as delivered
    assert figures["raw_mean_mm"] == pytest.approx((110 + 8 * 50) / 9)  # 30 mm further along x
    assert f"as solved, before smoothing (joints_raw.npz): {figures['raw_mean_mm']:.1f} mm" in out


def test_missing_joint_is_named(tmp_path):
    write_joints(tmp_path / "a.npz", np.zeros((2, 2, 3)), [0, 1], ["Hips", "Spine"])
    write_joints(tmp_path / "b.npz", np.zeros((2, len(NAMES), 3)), [0, 1])
    with pytest.raises(EvaluationError, match="l_hip"):
        joint_errors(tmp_path / "a.npz", tmp_path / "b.npz")


def test_no_common_frames_is_an_error(tmp_path):
    write_joints(tmp_path / "a.npz", np.zeros((2, len(NAMES), 3)), [0, 1])
    write_joints(tmp_path / "b.npz", np.zeros((2, len(NAMES), 3)), [5, 6])
    with pytest.raises(EvaluationError, match="share no frame"):
        joint_errors(tmp_path / "a.npz", tmp_path / "b.npz")
