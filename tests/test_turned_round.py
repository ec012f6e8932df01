"""The body turned round (core/tracking/turned_round.py): a pose's reflection through its frontal plane, fitted back
into the DOFs, and the tracker's check that keeps it where it explains the images better."""
import types

import numpy as np
import pytest

from markerless_mocap.core.tracking.turned_round import TurnedRound, frontal_normal, mirror_name


@pytest.mark.parametrize("name, partner", [
    ("LeftArm", "RightArm"), ("RightUpLeg", "LeftUpLeg"), ("LHipJoint", "RHipJoint"), ("RThumb", "LThumb"),
    ("mixamorig:LeftHand", "mixamorig:RightHand"), ("upper_arm.L", "upper_arm.R"), ("thigh_r", "thigh_l"),
    ("Spine1", "Spine1"), ("Head", "Head"), ("LowerBack", "LowerBack"), ("Hips", "Hips"),
])
def test_each_bone_finds_its_partner_by_the_usual_names(name, partner):
    assert mirror_name(name) == partner


def _heads(body, pose):
    return body.joint_positions(np.asarray(pose)[None])[0]


@pytest.mark.slow
def test_the_reflection_faces_the_other_way_and_twice_gives_the_pose_back():
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses

    body, _, gt, _ = ground_truth_poses("walk")
    turned = TurnedRound(body)
    # every joint angle has its mirror partner (l_ <-> r_, the spine's and neck's flexion and bending their own)
    named = {body.dof_names[j]: (body.dof_names[i], turned.dof_sign[j]) for j, i in enumerate(turned.dof_partner)}
    assert named["l_elbow.flex"] == ("r_elbow.flex", 1.0) and named["spine.bend"] == ("spine.bend", -1.0)
    for frame in (0, 20, 45):
        pose = gt[frame]
        once = turned.reflected(pose)
        twice = turned.reflected(once)
        heads, heads_once = _heads(body, pose), _heads(body, once)
        facing = frontal_normal(body, heads) @ frontal_normal(body, heads_once)
        back = np.sqrt(np.mean(np.sum((_heads(body, twice) - heads) ** 2, axis=1)))
        print(f"frame {frame}: facing dot {facing:.3f}, twice reflected rms {back * 1e3:.1f} mm")
        assert facing < -0.98
        assert back < 0.01
        assert np.linalg.norm(heads_once[body.root_bone] - heads[body.root_bone]) < 0.005  # turned on the spot


@pytest.mark.slow
def test_a_frame_left_facing_backwards_is_turned_round_and_a_right_one_is_not(monkeypatch):
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses
    from test_first_frame_review import _walk_tracker

    body, _, gt, _ = ground_truth_poses("walk")
    tracker, capture = _walk_tracker()
    searched = {}

    def search(energy_fn, history):  # frame 1's "search" leaves the body turned round; frame 2's finds the truth
        frame = len(tracker.estimates)
        pose = tracker.turned.reflected(gt[frame]) if frame == 1 else gt[frame]
        searched[frame] = pose
        estimate = tracker.to_relative(pose)
        return types.SimpleNamespace(estimate=estimate, energy=float(energy_fn(estimate[None])[0]), evaluations=1)

    try:
        tracker.initialise(0, initial_pose=gt[0])
        monkeypatch.setattr(tracker.optimizer, "track_frame", search)
        first, second = tracker.track(1), tracker.track(2, next_frame=None)
    finally:
        capture.close()
    error = {f: np.linalg.norm(_heads(body, p) - _heads(body, gt[f]), axis=1) for f, p in searched.items()}
    tracked = {1: np.linalg.norm(first.joints - _heads(body, gt[1]), axis=1),
               2: np.linalg.norm(second.joints - _heads(body, gt[2]), axis=1)}
    print(f"frame 1: searched (turned round) mean {error[1].mean() * 1e3:.0f} mm, tracked {tracked[1].mean() * 1e3:.1f}"
          f" mm; frame 2 tracked {tracked[2].mean() * 1e3:.1f} mm; turns {tracker.turns}")
    assert error[1].mean() > 0.1
    assert list(tracker.turns) == [1]
    assert tracker.turns[1]["energy_after"] < tracker.turns[1]["energy_before"]
    assert tracked[1].mean() < 0.03 and tracked[2].mean() < 0.03
