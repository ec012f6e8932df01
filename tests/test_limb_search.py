"""The first frame's limb-by-limb search (core/tracking/limb_search.py) on a synthetic energy with known minima."""
from types import SimpleNamespace

import numpy as np

from markerless_mocap.core.tracking.limb_search import limb_dofs, search_limbs
from markerless_mocap.core.optimizers import PoseSpace

ROLES = ["root"] * 6 + ["spine"] * 3 + ["neck"] * 3 + ["l_shoulder"] * 3 + ["r_shoulder"] * 3 + \
        ["l_elbow", "r_elbow"] + ["l_hip"] * 3 + ["r_hip"] * 3 + ["l_knee", "r_knee", "l_ankle", "r_ankle"]
D = len(ROLES)


def make_space():
    lower, upper = np.full(D, -1.5), np.full(D, 1.5)
    lower[:6], upper[:6] = -np.inf, np.inf
    translation = np.arange(D) < 3
    return PoseSpace.with_default_scale(lower, upper, [f"dof{i}" for i in range(D)], translation)


def test_limb_dofs_groups_each_limbs_roles():
    limbs = limb_dofs([SimpleNamespace(role=r) for r in ROLES])
    assert list(limbs) == ["left arm", "right arm", "left leg", "right leg"]
    assert limbs["left arm"].tolist() == [12, 13, 14, 18]
    assert limbs["right leg"].tolist() == [23, 24, 25, 27, 29]
    no_arms = limb_dofs([SimpleNamespace(role=r) for r in ROLES if "shoulder" not in r and "elbow" not in r])
    assert list(no_arms) == ["left leg", "right leg"]


def test_each_limb_leaves_a_wrong_basin_for_the_deeper_one():
    """Every limb sits in a local minimum (energy 2 above the global one, 1 rad away per DOF); the
    DOFs outside the limbs are at their optimum and must stay exactly where they are."""
    space = make_space()
    limbs = limb_dofs([SimpleNamespace(role=r) for r in ROLES])
    rng = np.random.default_rng(0)
    start = rng.uniform(-0.3, 0.3, D)
    truth = start.copy()
    for idx in limbs.values():
        truth[idx] = start[idx] + np.where(start[idx] > 0, -1.0, 1.0)
    calls = []

    def energy(X):
        calls.append(len(X))
        total = np.zeros(len(X))  # the held DOFs are at their optimum: they add nothing
        for idx in limbs.values():
            near = ((X[:, idx] - start[idx]) ** 2).sum(axis=1) / 0.3 ** 2 + 2.0
            far = ((X[:, idx] - truth[idx]) ** 2).sum(axis=1) / 0.3 ** 2
            total = total + np.minimum(near, far)
        return total

    x, e, evaluations = search_limbs(energy, space, start, limbs, seed=1, particles=100, iterations=10)
    assert evaluations == sum(calls)
    limb_idx = np.concatenate(list(limbs.values()))
    held = np.setdiff1d(np.arange(D), limb_idx)
    np.testing.assert_array_equal(x[held], start[held])
    assert np.abs(x[limb_idx] - truth[limb_idx]).max() < 0.1  # each limb in the deeper basin
    assert e < 0.5 and e == energy(x[None])[0]


def test_a_limb_that_cannot_improve_stays_put():
    space = make_space()
    limbs = limb_dofs([SimpleNamespace(role=r) for r in ROLES])
    start = np.linspace(-0.5, 0.5, D)

    def energy(X):
        return ((X - start) ** 2).sum(axis=1)

    polished = []
    x, e, _ = search_limbs(energy, space, start, limbs, particles=40, iterations=4,
                           polish=lambda pose: polished.append(1) or pose)
    np.testing.assert_array_equal(x, start)
    assert e == 0.0 and len(polished) == len(limbs)
