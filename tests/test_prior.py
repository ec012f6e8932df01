"""Anatomical prior: bandwidth rule on hand-made samples, density against the plain formula, gradient, I/O."""
import numpy as np
import pytest

from markerless_mocap.core.energy.prior import AnatomicalPrior, PriorError, second_neighbour_bandwidth


def test_bandwidth_is_the_largest_second_nearest_neighbour_distance():
    # 1-D samples 0, 1, 3, 7: 2nd-nearest other sample at distance 3, 2, 3, 6 -> h = 6.
    assert second_neighbour_bandwidth(np.array([[0.0], [1.0], [3.0], [7.0]])) == pytest.approx(6.0)
    # 2-D: unit square corners + a far point (10, 0).
    pts = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [10, 0]], float)
    # distances from (10,0): 9 to (1,0), sqrt(82) to (1,1), 10 to (0,0) -> 2nd = sqrt(82)
    assert second_neighbour_bandwidth(pts) == pytest.approx(np.sqrt(82))


def _naive_energy(prior, x):
    total = 0.0
    for g, idx in prior.groups.items():
        y, h = prior.samples[g], prior.bandwidths[g]
        L, d = y.shape
        k = (2 * np.pi) ** (-d / 2) * np.exp(-np.sum((x[idx] - y) ** 2, axis=1) / (2 * h * h))
        total += np.log(k.sum() / (L * h ** d))
    return -total / len(prior.groups)


def _training(seed=0, n=300):
    rng = np.random.default_rng(seed)
    return rng.normal(0, [0.1, 0.2, 0.3, 0.4, 0.2, 0.1, 0.5], (n, 7)) + np.sin(np.arange(7))


GROUPS = {"head": [1, 2], "upper": [3, 4, 5], "lower": [6]}


def test_energy_matches_the_parzen_formula_and_stays_finite_far_away():
    prior = AnatomicalPrior.fit(_training(), GROUPS, n_samples=200, seed=3, floor_sigmas=None)
    assert all(len(s) == 200 for s in prior.samples.values())
    x = np.random.default_rng(1).normal(0, 0.3, (6, 7)) + np.sin(np.arange(7))
    e = prior.energy(x)
    assert e == pytest.approx([_naive_energy(prior, xi) for xi in x], rel=1e-10)
    assert np.allclose(prior.energy(x[:, :]), [prior.energy(xi)[0] for xi in x])
    # DOF 0 is in no group: it does not change the energy.
    moved = x.copy()
    moved[:, 0] += 5
    assert np.array_equal(prior.energy(moved), e)
    far = prior.energy(np.full((1, 7), 1e3))
    assert np.isfinite(far).all() and far[0] > 1e4
    # Likely poses score lower than unlikely ones.
    assert prior.energy(np.sin(np.arange(7))[None])[0] < prior.energy(np.sin(np.arange(7))[None] + 1.0)[0]


def test_floor_bounds_the_penalty_far_from_the_data():
    exact = AnatomicalPrior.fit(_training(), GROUPS, n_samples=200, seed=3, floor_sigmas=None)
    floored = AnatomicalPrior.fit(_training(), GROUPS, n_samples=200, seed=3, floor_sigmas=3.0)
    near = np.sin(np.arange(7))[None]
    assert floored.energy(near) == pytest.approx(exact.energy(near))  # unchanged where data is
    far = np.full((2, 7), 50.0)
    # Far away: each group costs exactly one sample's kernel at 3 bandwidths; no pull any more.
    expected = 0.0
    for g, y in floored.samples.items():
        L, d = y.shape
        h = floored.bandwidths[g]
        expected -= -4.5 - np.log(L) - d * np.log(h) - 0.5 * d * np.log(2 * np.pi)
    assert floored.energy(far) == pytest.approx([expected / len(floored.groups)] * 2)
    assert np.all(floored.gradient(far) == 0)
    assert exact.energy(far)[0] > floored.energy(far)[0] + 1e3


def test_gradient_matches_finite_differences():
    prior = AnatomicalPrior.fit(_training(2), GROUPS, n_samples=100, seed=0)
    x = np.random.default_rng(4).normal(0, 0.3, (3, 7)) + np.sin(np.arange(7))
    g = prior.gradient(x)
    eps = 1e-6
    for i in range(7):
        dx = np.zeros(7)
        dx[i] = eps
        fd = (prior.energy(x + dx) - prior.energy(x - dx)) / (2 * eps)
        assert np.allclose(g[:, i], fd, rtol=1e-5, atol=1e-7)


def test_fit_is_seeded_and_save_load_round_trips(tmp_path):
    a = AnatomicalPrior.fit(_training(), GROUPS, n_samples=50, seed=7)
    b = AnatomicalPrior.fit(_training(), GROUPS, n_samples=50, seed=7)
    c = AnatomicalPrior.fit(_training(), GROUPS, n_samples=50, seed=8)
    assert np.array_equal(a.samples["upper"], b.samples["upper"])
    assert not np.array_equal(a.samples["upper"], c.samples["upper"])
    path = tmp_path / "prior.npz"
    a.save(path)
    loaded = AnatomicalPrior.load(path)
    x = np.random.default_rng(0).normal(0, 0.3, (4, 7))
    assert np.array_equal(loaded.energy(x), a.energy(x))
    assert loaded.bandwidths == a.bandwidths


def test_bad_training_data_and_files_give_clear_errors(tmp_path):
    with pytest.raises(PriorError, match="at least 3"):
        AnatomicalPrior.fit(np.zeros((2, 7)), GROUPS)
    with pytest.raises(PriorError, match="identical"):
        AnatomicalPrior.fit(np.ones((10, 7)), GROUPS)
    with pytest.raises(PriorError, match="NaN"):
        AnatomicalPrior.fit(np.full((10, 7), np.nan), GROUPS)
    prior = AnatomicalPrior.fit(_training(), GROUPS, n_samples=20)
    with pytest.raises(PriorError, match="7 DOF"):
        prior.energy(np.zeros((1, 6)))
    with pytest.raises(FileNotFoundError, match="from_motion"):
        AnatomicalPrior.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, something=np.zeros(3))
    with pytest.raises(PriorError, match="not a saved anatomical prior"):
        AnatomicalPrior.load(bad)


def test_from_motion_maps_frames_spread_over_every_clip(monkeypatch):
    from markerless_mocap.core.mocap import to_dof as motion_to_dof

    class Clip:
        def __init__(self, n, offset):
            self.n_frames, self.offset = n, offset

    class Body:
        prior_groups = {"head": [1, 2], "upper": [3, 4, 5], "lower": [6]}

    asked = []

    def fake_sequence(body, clip, frames=None, name_map=None):
        asked.append((clip.offset, np.asarray(frames)))
        f = np.asarray(frames, float)[:, None]
        poses = clip.offset + np.sin(f * np.arange(1, 8) * 0.37)  # a distinct pose per frame
        return poses, np.zeros(len(f))

    monkeypatch.setattr(motion_to_dof, "dof_sequence_from_clip", fake_sequence)
    prior = AnatomicalPrior.from_motion(Body(), [Clip(1000, 0.0), Clip(50, 10.0)], n_samples=40, seed=0)
    (o1, f1), (o2, f2) = asked
    assert len(f1) == 40 and f1[0] == 0 and f1[-1] == 999  # 2 x 40 / 2 clips, first to last frame
    assert np.array_equal(f2, np.unique(np.linspace(0, 49, 40).round().astype(int)))
    assert all(len(s) == 40 for s in prior.samples.values())
    # Samples come from both clips (the second clip's poses are offset by 10).
    assert (prior.samples["lower"] > 5).any() and (prior.samples["lower"] < 5).any()


def test_beyond_the_joint_limits_is_impossible_within_them_nothing_changes(tmp_path):
    lower, upper = np.full(7, -np.inf), np.full(7, np.inf)
    lower[6], upper[6] = -0.2, 2.5  # DOF 6 a knee: straight at -0.2, fully bent at 2.5
    plain = AnatomicalPrior.fit(_training(), GROUPS, n_samples=100, seed=1)
    bounded = AnatomicalPrior.fit(_training(), GROUPS, n_samples=100, seed=1).bounded_by(lower, upper)
    inside = np.random.default_rng(3).normal(0, 0.3, (5, 7)) + np.sin(np.arange(7))
    inside[:, 6] = np.clip(inside[:, 6], -0.2, 2.5)
    assert np.array_equal(bounded.energy(inside), plain.energy(inside))
    assert np.array_equal(bounded.gradient(inside), plain.gradient(inside))
    past = inside.copy()
    past[:, 6] = -0.2 - np.deg2rad(10)  # hyper-extended by 10 degrees
    assert np.all(bounded.energy(past) > plain.energy(past) + 500)
    eps, x = 1e-6, past[:1]
    fd = (bounded.energy(x + [0, 0, 0, 0, 0, 0, eps]) - bounded.energy(x - [0, 0, 0, 0, 0, 0, eps])) / (2 * eps)
    assert bounded.gradient(x)[0, 6] == pytest.approx(fd[0], rel=1e-5)
    path = tmp_path / "prior.npz"
    bounded.save(path)
    assert np.array_equal(AnatomicalPrior.load(path).energy(past), bounded.energy(past))
    with pytest.raises(PriorError, match="7 lower and upper"):
        plain.bounded_by(lower[:6], upper[:6])


def test_an_unseen_possible_pose_is_possible_a_hyperextended_knee_is_not():
    """The product's prior (walking and jumping clips, mapped on the walk subject): sitting on a chair and both
    arms straight up are far from every training pose, yet cost no more than the floor does anywhere; a knee bent
    20 degrees backwards costs hundreds of times more."""
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses, scene_dir

    from markerless_mocap.core.tracking.motion_library import build_motion_models, scene_exclusion

    body, _, poses, _ = ground_truth_poses("walk")
    prior, _ = build_motion_models(body, exclude=scene_exclusion(scene_dir("walk")))
    dof = {n: i for i, n in enumerate(body.dof_names)}
    walking = poses[30]
    sitting = walking.copy()
    for side in ("l", "r"):
        sitting[dof[f"{side}_hip.flex"]], sitting[dof[f"{side}_knee.flex"]] = 1.55, 1.6
    arms_up = walking.copy()
    for side in ("l", "r"):
        arms_up[dof[f"{side}_shoulder.flex"]], arms_up[dof[f"{side}_elbow.flex"]] = 2.9, 0.0
    for pose in (sitting, arms_up):
        assert np.all((pose >= body.lower) & (pose <= body.upper))  # possible: within every joint's limits
    far = np.full((1, body.n_dof), 0.0)
    far[0, 6:] = np.where(np.isfinite(body.upper[6:]), body.upper[6:], 0.0)  # every joint at its upper limit
    ceiling = float(prior.energy(far)[0])  # the floor's cost: as far from the data as the limits allow
    for pose in (sitting, arms_up):
        e = float(prior.energy(pose[None])[0])
        print(f"prior: walking {float(prior.energy(walking[None])[0]):.2f}, this pose {e:.2f}, floor {ceiling:.2f}")
        assert np.isfinite(e) and e <= ceiling + 1e-9
    knee_back = walking.copy()
    knee_back[dof["l_knee.flex"]] = body.lower[dof["l_knee.flex"]] - np.deg2rad(20)
    assert prior.energy(knee_back[None])[0] > 100 * max(1.0, abs(ceiling))
