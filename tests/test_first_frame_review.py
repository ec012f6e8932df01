"""The first frame looked at again once the second is solved (core/tracking/first_frame_review.py): on walk, a
first frame whose search left the right arm raised is replaced by the second frame's pose fitted to the first
frame's images; a first frame that is right stays exactly as it was."""
import numpy as np
import pytest

from markerless_mocap.core.tracking import first_frame_review, tracker as tracker_module
from markerless_mocap.core.tracking.first_frame_review import REVIEW_DISTANCE, reviewed

pytestmark = pytest.mark.slow


def _walk_tracker():
    from scene_helpers import ground_truth_poses, scene_dir

    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.tracking.motion_library import build_motion_models, scene_exclusion
    from markerless_mocap.core.tracking.settings import TrackingSettings

    body = ground_truth_poses("walk")[0]
    capture = load_capture(scene_dir("walk"))
    prior, dynamics = build_motion_models(body, fps=capture.frames.fps, exclude=scene_exclusion(scene_dir("walk")))
    tracker = tracker_module.Tracker(body, capture, TrackingSettings(particles=100, iterations=8, prefetch=False),
                                     prior=prior, dynamics=dynamics)
    return tracker, capture


def _first_two_frames(monkeypatch, first_pose):
    """Walk's frames 0 and 1, the first frame's search replaced by one that returns `first_pose` (absolute)."""
    tracker, capture = _walk_tracker()
    monkeypatch.setattr(tracker_module, "search_first_frame",
                        lambda *args, **kw: (tracker.to_relative(first_pose), 0))
    monkeypatch.setattr(tracker, "_refine", lambda estimate: estimate)  # the first frame as the "search" left it
    try:
        first = tracker.initialise(0)
        searched = first.pose.copy()
        monkeypatch.undo()
        tracker.track(1, next_frame=None)
    finally:
        capture.close()
    return tracker, first, searched


def _error(body, pose, truth):
    return np.linalg.norm(body.joint_positions(pose[None])[0] - body.joint_positions(truth[None])[0], axis=1)


def test_a_first_frame_with_a_wrong_arm_is_replaced_once_the_second_is_solved(monkeypatch):
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses

    body, _, gt, _ = ground_truth_poses("walk")
    wrong = gt[0].copy()
    wrong[body.dof_names.index("r_shoulder.abd")] += 1.3  # the right arm raised sideways, ~0.5 m off at the hand
    tracker, first, searched = _first_two_frames(monkeypatch, wrong)
    before, after = _error(body, searched, gt[0]), _error(body, first.pose, gt[0])
    print(f"frame 0, largest joint error: searched {before.max():.3f} m, reviewed {after.max():.3f} m; "
          f"mean {before.mean() * 1e3:.1f} -> {after.mean() * 1e3:.1f} mm; {tracker.first_frame_review}")
    assert before.max() > 0.25
    assert tracker.first_frame_review is not None and tracker.first_frame_review["frame"] == 0
    assert after.max() < 0.1 and after.mean() < 0.5 * before.mean()
    assert tracker.estimates[0] is first  # what the result writer holds is the replaced frame
    np.testing.assert_allclose(tracker.to_absolute(tracker.history[-2]), first.pose, atol=1e-9)
    assert tracker.first_evidence is None  # the first frame's images are let go


def test_a_right_first_frame_stays_as_it_was(monkeypatch):
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses

    body, _, gt, _ = ground_truth_poses("walk")
    tracker, first, searched = _first_two_frames(monkeypatch, gt[0])
    assert tracker.first_frame_review is None
    np.testing.assert_array_equal(first.pose, searched)


def test_the_verdict_needs_both_a_lower_energy_and_a_far_joint():
    class Body:  # joints = the pose read as one point per three numbers
        @staticmethod
        def joint_positions(poses):
            return np.asarray(poses, dtype=float).reshape(len(poses), -1, 3)

    a = np.zeros(6)
    far, near = a.copy(), a.copy()
    far[3] = REVIEW_DISTANCE * 1.5
    near[3] = REVIEW_DISTANCE * 0.5
    assert reviewed(Body, a, 2.0, far, 1.0)["largest_joint_move_m"] == pytest.approx(REVIEW_DISTANCE * 1.5)
    assert reviewed(Body, a, 2.0, near, 1.0) is None  # right enough: kept, so later frames do not move
    assert reviewed(Body, a, 1.0, far, 2.0) is None  # explains the first frame worse
    assert first_frame_review.FirstFrameEvidence.__dataclass_fields__.keys() >= {"observation", "others"}
