"""The view that pulled a refused estimate (core/tracking/pulling_view.py): each view scored alone on the refused
estimate and the prediction; the one that favours the refused estimate most is named, the energy left as it came."""
import numpy as np

from markerless_mocap.core.evidence.keypoints import KeypointTargets
from markerless_mocap.core.tracking.pulling_view import only_views, pulling_view, view_gains


class ViewEnergy:
    """An energy whose views each prefer a root x of their own (view 2: another person 0.4 m away); the image terms
    listen to view_weights, the landmark term to the keypoints' weights, as the tracker's EnergyModel does."""

    def __init__(self, preferred):
        self.preferred = np.asarray(preferred, dtype=np.float64)
        self.view_weights = None
        self.keypoints = KeypointTargets(np.zeros((len(preferred), 4, 2)), np.ones((len(preferred), 4)),
                                         np.ones(len(preferred)))

    def set_view_weights(self, weights):
        self.view_weights = None if weights is None or np.all(np.asarray(weights) == 1) else np.asarray(weights)

    def __call__(self, poses):
        w = np.ones(len(self.preferred)) if self.view_weights is None else self.view_weights
        per_view = (poses[:, :1] - self.preferred[None]) ** 2
        landmarks = per_view @ self.keypoints.weight[:, 0] / max(self.keypoints.weight[:, 0].sum(), 1e-9)
        return per_view @ w / w.sum() + landmarks


def test_the_view_that_favours_the_refused_estimate_is_named_and_the_energy_left_as_it_came():
    energy = ViewEnergy([0.0, 0.02, 0.4, -0.01])
    keypoints = energy.keypoints
    refused, predicted = np.array([0.3, 1.0]), np.array([0.0, 1.0])
    in_play = np.array([True, True, True, True])
    gains = view_gains(energy, energy, in_play, refused, predicted)
    # alone, view v scores (x - p_v)^2 twice (its images and its landmarks): predicted minus refused
    expected = 2 * ((0.0 - energy.preferred) ** 2 - (0.3 - energy.preferred) ** 2)
    np.testing.assert_allclose(gains, expected)
    assert pulling_view(gains) == 2
    assert energy.view_weights is None and energy.keypoints is keypoints
    # a view out of play is not scored and not named
    in_play[2] = False
    gains = view_gains(energy, energy, in_play, refused, predicted)
    assert np.isnan(gains[2]) and pulling_view(gains) is None  # no view left favours the refused estimate


def test_no_view_is_left_out_below_three_views_or_when_none_favours_the_refused_estimate():
    assert pulling_view([0.5, -0.1, np.nan, np.nan]) is None  # two views in play
    assert pulling_view([-0.5, -0.1, -0.2]) is None
    assert pulling_view([-0.5, 0.1, -0.2]) == 1


def test_only_views_weights_the_others_zero():
    keypoints = KeypointTargets(np.zeros((3, 2, 2)), np.full((3, 2), 0.7), np.ones(3))
    kept = only_views(keypoints, [True, False, True])
    np.testing.assert_array_equal(kept.weight, [[0.7, 0.7], [0.0, 0.0], [0.7, 0.7]])
    np.testing.assert_array_equal(keypoints.weight, np.full((3, 2), 0.7))
