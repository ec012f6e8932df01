"""Telling the actor from someone else by clothes (core/evidence/appearance.py, core/tracking/clothes_check.py):
signatures of a drawn figure under changed light and with other clothes, and the check's verdict per view."""
import cv2
import numpy as np

from markerless_mocap.core.evidence.appearance import (HIPS, KNEES, SHOULDERS, clothes_signature, likeness,
                                                       picture_reference)
from markerless_mocap.core.tracking.clothes_check import MIN_LIKENESS, ClothesCheck

BGR = {"rust": (40, 70, 170), "navy": (90, 40, 25), "green": (50, 150, 40), "khaki": (90, 150, 170)}


def figure(shirt, trousers, light=(1.0, 1.0, 1.0), shift=0, seed=0):
    """A 240x320 picture of a grey room with a standing figure (shirt torso, trousers legs), the light scaled per
    channel (BGR), sensor noise; and its landmarks (33,2) with the shoulders, hips and knees placed."""
    rng = np.random.default_rng(seed)
    img = np.full((320, 240, 3), 128, np.float64)
    img[290:] = (100, 110, 115)  # a floor of another grey
    x = 120 + shift
    uv = np.full((33, 2), np.nan)
    uv[SHOULDERS[0]], uv[SHOULDERS[1]] = (x + 30, 80), (x - 30, 80)
    uv[HIPS[0]], uv[HIPS[1]] = (x + 20, 170), (x - 20, 170)
    uv[KNEES[0]], uv[KNEES[1]] = (x + 22, 240), (x - 22, 240)
    cv2.fillConvexPoly(img, np.round(uv[[11, 12, 24, 23]]).astype(np.int32), BGR[shirt])
    for hip, knee in zip(HIPS, KNEES):
        cv2.line(img, tuple(int(v) for v in uv[hip]), tuple(int(v) for v in uv[knee] + (0, 60)), BGR[trousers], 24)
    img = img * np.asarray(light)[None, None] + rng.normal(0, 4, img.shape)
    visible = np.zeros(33, bool)
    visible[[*SHOULDERS, *HIPS, *KNEES]] = True
    return np.clip(img, 0, 255).astype(np.uint8), uv, visible


def signature(*args, **kw):
    img, uv, visible = figure(*args, **kw)
    return clothes_signature(img, uv, visible)


def test_the_same_clothes_under_a_dimmer_warmer_light_are_alike_and_other_clothes_are_not():
    actor = [signature("rust", "navy", seed=1)]
    same = signature("rust", "navy", light=(0.45, 0.5, 0.62), shift=30, seed=2)  # dimmer and warmer, moved
    assert set(same) == {"torso", "thighs"}
    assert likeness(same, actor) > 0.8
    other = signature("green", "khaki", seed=3)
    assert likeness(other, actor) < MIN_LIKENESS
    # the shirt alone tells: same trousers, another shirt
    assert likeness(signature("green", "navy", seed=4), actor) < likeness(same, actor) - 0.3


def test_the_picture_reference_follows_the_light():
    img, _, _ = figure("rust", "navy")
    dim, _, _ = figure("rust", "navy", light=(0.5, 0.5, 0.5))
    warm, _, _ = figure("rust", "navy", light=(0.5, 0.7, 0.9))
    ref = picture_reference(img)
    np.testing.assert_allclose(picture_reference(dim), 0.5 * ref, rtol=0.03)
    np.testing.assert_allclose(picture_reference(warm), (0.5, 0.7, 0.9) * ref, rtol=0.03)


def test_landmarks_that_outline_nothing_give_no_signature():
    img, uv, visible = figure("rust", "navy")
    assert clothes_signature(img, uv, np.zeros(33, bool)) is None
    only_torso = visible.copy()
    only_torso[list(KNEES)] = False
    assert set(clothes_signature(img, uv, only_torso)) == {"torso"}
    assert likeness(None, [clothes_signature(img, uv, visible)]) is None


class View:
    """A view's evidence as the check reads it."""

    def __init__(self, clothes, found=True):
        self.clothes, self.found = clothes, found


def test_the_check_learns_the_first_frames_and_names_the_view_of_someone_else():
    check = ClothesCheck(learn_frames=2)
    assert not check.ready
    actor = [View(signature("rust", "navy", seed=s)) for s in range(3)]
    check.learn(actor, np.array([True, True, False]))
    check.learn(actor, np.array([True, True, True]))
    assert check.ready and len(check.exemplars) == 5
    check.learn([View(signature("green", "khaki"))], np.array([True]))  # past the learning frames: not taken
    assert len(check.exemplars) == 5
    frame = [View(signature("rust", "navy", light=(0.7, 0.75, 0.8), seed=7)), View(signature("green", "khaki")),
             View(None), View(signature("green", "khaki"), found=False)]
    unlike, like = check.unlike(frame)
    assert unlike.tolist() == [False, True, False, False]
    assert like[0] > 0.8 and like[1] < MIN_LIKENESS and np.isnan(like[2:]).all()

    # every view unlike the actor: the actor (or the light) has changed, not every view's person
    nobody_alike = [View(signature("green", "khaki", seed=s)) for s in range(3)]
    none_unlike, none_like = check.unlike(nobody_alike)
    assert not none_unlike.any() and (none_like < MIN_LIKENESS).all()

    again = ClothesCheck(learn_frames=2)
    again.restore(check.state())
    assert again.learned_frames == 2
    np.testing.assert_array_equal(again.unlike(frame)[1], like)
    fresh = ClothesCheck()
    fresh.restore(None)  # a checkpoint from before the check: learned again from the next frames
    assert not fresh.ready


def test_the_tracker_drops_every_landmark_of_the_view_dressed_unlike_the_actor_and_reports_it():
    """Tracker._set_aside_unlike on a frame where cam2's crop holds someone in other clothes: cam2's landmark weights
    go to zero, the others' stay, report.json's map gets the camera and its likeness; before anything is learned
    nothing is dropped."""
    from types import SimpleNamespace

    from markerless_mocap.core.evidence.keypoints import KeypointTargets
    from markerless_mocap.core.tracking.tracker import Tracker

    cams = [SimpleNamespace(name=f"cam{i}") for i in (1, 2, 3)]
    weight = np.ones((3, 5))
    energy = SimpleNamespace(keypoints=KeypointTargets(np.zeros((3, 5, 2)), weight.copy(), np.ones(3)))
    evidence = [View(signature("rust", "navy", seed=11)), View(signature("green", "khaki", seed=12)),
                View(signature("rust", "navy", light=(0.8, 0.8, 0.9), seed=13))]
    check = ClothesCheck()
    tracker = SimpleNamespace(energy=energy, capture=SimpleNamespace(cameras=cams), clothes=check,
                              evidence=evidence, unlike_clothes={})
    assert not Tracker._set_aside_unlike(tracker, 7).any()  # nothing learned yet
    check.learn([View(signature("rust", "navy", seed=s)) for s in range(3)], np.ones(3, bool))
    unlike = Tracker._set_aside_unlike(tracker, 7)
    assert unlike.tolist() == [False, True, False]
    np.testing.assert_array_equal(energy.keypoints.weight, [[1] * 5, [0] * 5, [1] * 5])
    assert list(tracker.unlike_clothes) == [7] and list(tracker.unlike_clothes[7]) == ["cam2"]
    assert tracker.unlike_clothes[7]["cam2"] < MIN_LIKENESS
