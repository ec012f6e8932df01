"""The person leaving the picture in one view: that view is left out of the image terms for those
frames (its predicted joints mostly outside the image, no person found by the learned model, or a
silhouette that is no person), and tracking goes on with the other views at a bounded error."""
import numpy as np
import pytest

from markerless_mocap.core.capture.camera import Camera
from markerless_mocap.core.evidence.view_presence import share_inside, views_in_play

K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
CAM = Camera("front", K, [], np.eye(3), [0, 0, 4.0], 640, 480)  # looks along +z at the origin from z = -4
BODY = np.array([[0, y, 0] for y in np.linspace(-0.9, 0.9, 10)])  # a 1.8 m column of joints at the origin


def test_share_inside_counts_joints_projecting_into_the_image():
    assert share_inside(CAM, BODY) == 1.0
    assert share_inside(CAM, BODY + [3.0, 0, 0]) == 0.0  # walked 3 m to the side: out of the picture
    assert share_inside(CAM, BODY + [0, 0, -5.0]) == 0.0  # behind the camera
    assert 0.2 < share_inside(CAM, BODY + [0, 1.5, 0]) < 0.8  # half out at the bottom


class _Evidence:
    def __init__(self, found):
        self.found = found


def test_views_in_play_rules():
    cams = [CAM, CAM, CAM]
    assert views_in_play(cams, BODY).tolist() == [True, True, True]
    evidence = [_Evidence(True), _Evidence(False), _Evidence(True)]
    assert views_in_play(cams, BODY, evidence).tolist() == [True, False, True]
    person, picture = np.full(3, 1000.0), np.full(3, 640 * 480.0)
    area = np.array([900.0, 50.0, 200000.0])  # a person; almost nothing (cropped out); most of the picture (blank)
    assert views_in_play(cams, BODY, None, area, person, picture).tolist() == [True, False, False]
    assert views_in_play(cams, BODY + [3.0, 0, 0]).tolist() == [True, True, True]  # none qualifies: keep all


@pytest.mark.bpy
def test_tracking_goes_on_when_the_person_vanishes_from_one_view(tmp_path):
    """walk, cam2's frames 3-9 replaced by its empty plate (the person is gone from that view), the
    paper's silh+edge likelihood, 40 x 6, seeds 0 and 1, from the true first pose. Measured (seed 0, older
    features): with the view left out, frames 3-9 at 23.5-39.4 mm (mean 30.3); with every view kept,
    31.3-51.5 mm (mean 42.5). At this small budget one seed's worst frame moves by 10-15 mm with any change
    to the features: seeds 0-4 left out, mean of frames 3-9 25.3-34.2 mm, worst frame 30.7-47.5 mm; hence two
    seeds and bounds on their mean and worst."""
    pytest.importorskip("bpy")
    import cv2

    from capture_variants import copy_capture, rewrite_video
    from scene_helpers import ground_truth_poses, scene_dir
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.tracking.motion_library import build_motion_models, scene_exclusion
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.core.tracking.tracker import Tracker, run_tracker

    body, _, truth, _ = ground_truth_poses("walk")
    folder = copy_capture(tmp_path / "walk")
    plate = cv2.imread(str(folder / "background" / "cam2.png"))
    gone = range(3, 10)
    rewrite_video(folder / "videos" / "cam2.mp4", edit=lambda i, img: plate.copy() if i in gone else img)
    capture = load_capture(folder)
    prior, dynamics = build_motion_models(body, fps=capture.frames.fps, exclude=scene_exclusion(scene_dir("walk")))
    gone_means, worst = [], []
    for seed in (0, 1):
        tracker = Tracker(body, capture, TrackingSettings(particles=40, iterations=6, seed=seed,
                                                          likelihood="silh+edge"), prior=prior, dynamics=dynamics)
        estimates = run_tracker(tracker, range(0, 13), initial_pose=truth[0])
        error_mm = {e.frame: float(np.linalg.norm(body.joint_positions(e.pose[None])[0] - body.joint_positions(
            truth[e.frame][None])[0], axis=-1).mean() * 1000) for e in estimates}
        print(f"seed {seed} error per frame (mm):", {f: round(v, 1) for f, v in error_mm.items()})
        assert tracker.views_left_out == {f: ["cam2"] for f in gone}
        gone_means.append(np.mean([error_mm[f] for f in gone]))
        worst.append(max(error_mm.values()))
    capture.close()
    assert np.mean(gone_means) < 34 and max(worst) < 50
