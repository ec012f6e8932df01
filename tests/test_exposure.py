"""Exposure matching: the background follows the frame's light, also through a non-linear tone curve.

Known answers: a frame made from the plate by a per-channel tone curve (gamma and a white-balance
shift, as filmic or video cameras do when the light dims) must be matched to within the noise, and a
person in such a frame must be found without the walls turning into foreground; a single gain cannot
do that, which is why the curve is the default."""
import numpy as np
import pytest

from markerless_mocap.core.evidence import BackgroundModel, FeatureInputError, silhouette_iou
from markerless_mocap.core.evidence.exposure import (apply_tone_curve, channel_gain, fit_tone_curve, isotonic,
                                                     match_exposure)
from test_features import person_mask, textured_plate


def tone(image, gains=(0.55, 0.6, 0.75), gamma=1.6):
    """A dimmer, cooler light seen through a camera with a non-linear response (per channel)."""
    x = np.clip(image, 0, 255) / 255.0
    return 255.0 * np.asarray(gains, np.float32) * x ** gamma


@pytest.fixture(scope="module")
def plate():
    return textured_plate(240, 320, np.random.default_rng(5)).astype(np.float32)


def test_isotonic_pools_violators_with_their_weights():
    np.testing.assert_allclose(isotonic(np.array([1.0, 3.0, 2.0, 4.0]), np.ones(4)), [1, 2.5, 2.5, 4])
    np.testing.assert_allclose(isotonic(np.array([5.0, 1.0]), np.array([3.0, 1.0])), [4, 4])
    np.testing.assert_allclose(isotonic(np.arange(5.0), np.ones(5)), np.arange(5.0))


def test_tone_curve_recovers_a_known_monotone_map():
    rng = np.random.default_rng(0)
    source = rng.uniform(5, 250, 20000)
    target = 255 * (source / 255) ** 0.5 + rng.normal(0, 1.0, source.size)
    target[:200] = 250                       # a few outliers (the subject) must not bend the curve
    knots = fit_tone_curve(source, target)
    assert np.all(np.diff(knots[1]) >= 0)
    probe = np.linspace(20, 240, 50)
    assert np.abs(apply_tone_curve(probe, knots) - 255 * (probe / 255) ** 0.5).max() < 3.0
    assert fit_tone_curve(np.full(10, 100.0), np.full(10, 50.0)) is None   # too few samples: no curve


@pytest.mark.parametrize("model", ["curve", "gain"])
def test_linear_exposure_change_is_matched_by_both_models(plate, model):
    frame = plate * np.array([0.7, 0.8, 0.9], np.float32)
    matched = match_exposure(plate, frame, model)
    assert np.median(np.abs(matched - frame)) < 1.0
    np.testing.assert_allclose(channel_gain(frame, plate), [0.7, 0.8, 0.9], atol=0.01)


def test_non_linear_change_needs_the_curve(plate):
    frame = tone(plate)
    curve_error = np.abs(match_exposure(plate, frame, "curve") - frame)
    gain_error = np.abs(match_exposure(plate, frame, "gain") - frame)
    assert np.percentile(curve_error, 95) < 2.0
    assert np.percentile(gain_error, 95) > 8.0     # what a gain leaves over bright and dark walls


def test_person_under_changed_light_is_found_without_false_walls(plate):
    rng = np.random.default_rng(2)
    truth = person_mask(240, 320, 150, 110)
    frame = tone(plate)
    frame[truth] = (40, 40, 150)                   # a red shirt, also under the new light
    frame = np.clip(frame + rng.normal(0, 2.0, frame.shape), 0, 255).astype(np.uint8)
    shot = np.clip(plate + rng.normal(0, 2.0, plate.shape), 0, 255).astype(np.uint8)
    iou = {m: silhouette_iou(BackgroundModel.from_plate(shot, exposure=m).silhouette(frame), truth)
           for m in ("curve", "gain", "none")}
    assert iou["curve"] >= 0.95, iou
    assert iou["gain"] < iou["curve"] and iou["none"] < iou["curve"], iou


def test_unknown_exposure_model_is_a_clear_error(plate):
    with pytest.raises(FeatureInputError, match="exposure must be one of"):
        BackgroundModel.from_plate(plate.astype(np.uint8), exposure="auto")
    with pytest.raises(ValueError, match="unknown exposure model"):
        match_exposure(plate, plate, "auto")


def test_tone_curve_from_a_strided_subsample_matches_the_full_fit():
    """Above _MAX_CURVE_SAMPLES (an HD frame) the curve is fitted on an even stride of the samples: its knots
    stay within a fraction of a grey level of the fit on every sample."""
    from markerless_mocap.core.evidence import exposure

    rng = np.random.default_rng(3)
    n = 3 * exposure._MAX_CURVE_SAMPLES
    source = rng.uniform(0, 255, n)
    target = 255 * (source / 255) ** 0.8 + rng.normal(0, 3, n)
    sub_x, sub_y = exposure.fit_tone_curve(source, target)
    limit = exposure._MAX_CURVE_SAMPLES
    try:
        exposure._MAX_CURVE_SAMPLES = n  # every sample
        full_x, full_y = exposure.fit_tone_curve(source, target)
    finally:
        exposure._MAX_CURVE_SAMPLES = limit
    assert len(sub_x) == len(full_x) == 32
    np.testing.assert_allclose(sub_x, full_x, atol=0.2)
    np.testing.assert_allclose(sub_y, full_y, atol=0.3)
    assert not np.array_equal(sub_y, full_y)  # the stride did take a subsample
