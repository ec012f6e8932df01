"""The root gate (core/tracking/root_gate.py): a solution whose root moved faster than a person can, or swerved from
its constant-velocity prediction more than a body can accelerate, is refused and the frame searched again around the
prediction; a fast but possible move passes untouched. On a synthetic energy
with known minima, then wired into the tracker on the walk scene."""
import dataclasses

import numpy as np
import pytest

from markerless_mocap.core.optimizers import PoseSpace
from markerless_mocap.core.tracking.root_gate import (FIRST_STEP_SLACK, MAX_ROOT_ACCELERATION, MAX_ROOT_SPEED,
                                                      ROOT_JITTER, SWERVE_SCATTER, RootGate, hold_root,
                                                      root_step_limit, root_swerve_limit)

D = 30
T, R = np.arange(3), np.arange(3, 6)  # root translation, root rotation
FPS = 30.0


def make_space():
    lower, upper = np.full(D, -1.5), np.full(D, 1.5)
    lower[:6], upper[:6] = -np.inf, np.inf
    return PoseSpace.with_default_scale(lower, upper, [f"dof{i}" for i in range(D)], np.arange(D) < 3)


def walking_history(speed=1.2):
    """Two solved frames of a person walking along x at `speed` m/s, joints bent a little."""
    a = np.linspace(-0.2, 0.2, D)
    a[T] = [0.0, 0.0, 0.95]
    b = a.copy()
    b[0] += speed / FPS
    return [a, b]


def tracking_gate(space, history, **kw):
    """A gate past its first step: frame 0 initialised, frame 1 (history[1]) solved at walking pace."""
    gate = RootGate(space, T, R, FPS, **kw)
    gate.start(0)
    assert gate.check(history[1], 0.5, 10, 1, history[:1], None)[0] is history[1]
    return gate


def two_basins(near, far, near_depth=5.0):
    """An energy with its deepest minimum at `far` (another person) and one `near_depth` higher at `near`."""
    scale = make_space().scale

    def energy(X):
        X = np.atleast_2d(X)
        e_near = (((X - near) / scale) ** 2).sum(axis=1) + near_depth
        e_far = (((X - far) / scale) ** 2).sum(axis=1)
        return np.minimum(e_near, e_far)
    return energy


def test_the_bound_follows_the_frame_rate_and_the_frames_apart():
    assert root_step_limit(1, 30) == pytest.approx(MAX_ROOT_SPEED / 30 + ROOT_JITTER)
    assert root_step_limit(1, 60) == pytest.approx(MAX_ROOT_SPEED / 60 + ROOT_JITTER)
    assert root_step_limit(3, 30) == pytest.approx(3 * MAX_ROOT_SPEED / 30 + ROOT_JITTER)
    # the switch: 27.6 m/s between two frames (1.5 m within 10 frames) is over it at 30 and 60 fps
    assert 27.6 / 30 > root_step_limit(1, 30) and 27.6 / 60 > root_step_limit(1, 60)
    for bad in (0, -30, None):
        with pytest.raises(ValueError, match="frame rate"):
            root_step_limit(1, bad)


def test_the_swerve_bound_is_a_constant_acceleration_over_the_frames():
    """Positions under a constant acceleration a, the velocity taken over the last t_before seconds and carried t on,
    land a t (t + t_before) / 2 from the prediction; the bound is that at MAX_ROOT_ACCELERATION plus the estimate's
    own swerve."""
    a, fps = MAX_ROOT_ACCELERATION, 30.0
    for apart, before in ((1, 1), (2, 1), (1, 3)):
        times = np.array([-before, 0, apart]) / fps
        x = 0.7 * times + a * times ** 2 / 2  # walking on at 0.7 m/s, accelerating
        predicted = x[1] + (x[1] - x[0]) / before * apart
        assert root_swerve_limit(apart, before, fps) == pytest.approx(abs(x[2] - predicted) + SWERVE_SCATTER)
    # at 30 fps the bound is 0.156 m: the true hips of every sample scene stray at most 0.031 m
    assert 0.15 < root_swerve_limit(1, 1, 30) < 0.16
    with pytest.raises(ValueError, match="frame rate"):
        root_swerve_limit(1, 1, 0)


def steady_gate(space, speed, frames, energy=None, **kw):
    """A gate fed `frames` solved frames of a walk along x at `speed` m/s, each passing: returns (gate, history)."""
    history = walking_history(speed)
    gate = tracking_gate(space, history, **kw)
    for frame in range(2, frames):
        nxt = 2 * history[-1] - history[-2]
        assert gate.check(nxt, 0.0, 0, frame, history, energy)[0] is nxt
        history = [history[-1], nxt]
    return gate, history


def test_stepping_onto_another_person_at_a_walkers_bound_is_refused():
    """Walking at 0.5 m/s, the estimate steps 0.3 m sideways in one frame (9 m/s: under the speed bound, as the
    three-camera crossing's switch does frame after frame): it swerves 0.3 m from the prediction, more than a body's
    acceleration allows, and the frame is searched again around the prediction."""
    space = make_space()
    gate, history = steady_gate(space, 0.5, 4)
    near = 2 * history[-1] - history[-2]
    far = near.copy()
    far[T] += [0.0, 0.3, 0.0]
    assert np.linalg.norm(far[T] - history[-1][T]) < root_step_limit(1, FPS)  # the speed bound lets it through
    energy = two_basins(near, far)
    asked = []
    gate.set_aside = lambda refused, predicted: asked.append((refused, predicted)) or ["cam2"]
    found, found_energy, _ = gate.check(far.copy(), float(energy(far)[0]), 0, 4, history, energy)
    assert np.linalg.norm(found[T] - near[T]) < 0.05
    assert found_energy == pytest.approx(float(energy(found)[0]))
    assert [g["frame"] for g in gate.gated] == [4]
    assert gate.gated[0]["off_prediction_m"] == pytest.approx(0.3, abs=1e-3)
    assert gate.gated[0]["kept_off_prediction_m"] <= gate.gated[0]["limit_m"] + 1e-9
    # the evidence that pulled it was asked for before the re-search, with the refused estimate and the prediction
    assert len(asked) == 1 and np.array_equal(asked[0][0], far) and np.allclose(asked[0][1][T], near[T])
    assert gate.gated[0]["views_left_out"] == ["cam2"]


def test_a_hard_acceleration_passes_untouched():
    """A take-off at 3 g (30 m/s^2 upwards, for five frames after a steady walk) and a stop from 2 m/s within four
    frames: nothing is searched."""
    space = make_space()

    def never(X):
        raise AssertionError("the gate searched a possible move")

    for push in ([0.0, 0.0, 30.0], [-15.0, 0.0, 0.0]):
        gate, history = steady_gate(space, 2.0, 4, never)
        velocity = (history[-1] - history[-2]) * FPS
        for frame in range(4, 9):
            velocity[T] += np.asarray(push) / FPS
            nxt = history[-1] + velocity / FPS
            assert gate.check(nxt, 0.0, 0, frame, history, never)[0] is nxt
            history = [history[-1], nxt]
        assert gate.gated == []


def test_a_reset_history_does_not_hide_a_step():
    """The tracker resets its history to the frame's own estimate when it turns the body round: the gate measures
    from the roots it solved, so a turned estimate 0.25 m off the walk is still refused, and its state (the roots
    solved last) survives a checkpoint."""
    space = make_space()
    gate, history = steady_gate(space, 1.5, 4)

    def flat(X):
        return np.zeros(len(X))

    swerved = 2 * history[-1] - history[-2]
    swerved[T] += [0.0, 0.25, 0.0]  # 0.25 m off the walk's prediction, 7.6 m/s
    restored = RootGate(space, T, R, FPS, particles=20, iterations=2)
    restored.restore(gate.state())
    for g in (gate, restored):
        found = g.check(swerved.copy(), 0.0, 0, 4, [swerved, swerved], flat)[0]
        assert [x["frame"] for x in g.gated] == [4] and g.gated[0]["off_prediction_m"] == pytest.approx(0.25, abs=1e-3)
        assert np.linalg.norm(found[T] - (2 * history[-1] - history[-2])[T]) <= root_swerve_limit(1, 1, FPS) + 1e-9
    assert gate.state()["last_frame"] == 4
    np.testing.assert_allclose(gate.state()["velocity"][0], (history[-1] - history[-2])[T])  # kept from before
    old = RootGate(space, T, R, FPS)
    old.restore({"last_frame": 3, "first_step": False})  # a checkpoint from before the roots were kept
    assert old.check(swerved, 0.0, 0, 4, history, flat)[0] is swerved and old.gated == []


def test_coming_back_to_the_long_track_passes():
    """Walking at 1 m/s for a second, the model is pulled 0.3 m sideways over three frames (each within the swerve
    bound, as a slow switch is), then jumps back onto the walk: a swerve of 0.3 m, but back towards where the
    walk of a third of a second ago leads, so it passes; jumping 0.3 m further away is refused."""
    space = make_space()

    def flat(X):
        return np.zeros(len(X))

    for back, refused in ((True, []), (False, [34])):
        gate, history = steady_gate(space, 1.0, 31)
        for frame in (31, 32, 33):
            nxt = history[-1] + np.r_[1.0 / FPS, 0.1, np.zeros(D - 2)]
            assert gate.check(nxt, 0.0, 0, frame, history, flat)[0] is nxt
            history = [history[-1], nxt]
        step = history[-1].copy()
        step[T] += [1.0 / FPS, -0.3 if back else 0.3, 0.0]
        gate.check(step, 0.0, 0, 34, history, flat)
        assert [g["frame"] for g in gate.gated] == refused


def test_hold_root_moves_only_roots_beyond_the_ball():
    centre = np.array([1.0, 2.0, 0.9])
    X = np.zeros((2, D))
    X[0, T] = centre + [0.1, 0.0, 0.0]
    X[1, T] = centre + [3.0, 4.0, 0.0]
    X[:, 10] = 0.7
    held = hold_root(X, centre, 0.5, T)
    np.testing.assert_array_equal(held[0], X[0])
    np.testing.assert_allclose(held[1, T], centre + [0.3, 0.4, 0.0])
    np.testing.assert_array_equal(held[:, 3:], X[:, 3:])


def test_a_jump_of_the_root_is_refused_and_the_frame_searched_again():
    """The frame's search found the deeper minimum 1.5 m away (the other person): the gate refuses it, searches
    around the prediction and keeps the near minimum, the person walking on; the particles follow."""
    space = make_space()
    history = walking_history()
    near = 2 * history[1] - history[0]  # where the person walks on to
    near[12:16] += 0.15  # and an arm moved
    far = near.copy()
    far[T] += [0.3, 1.47, 0.0]  # 1.5 m away: 45 m/s at 30 fps
    energy = two_basins(near, far)
    steps = []
    gate = tracking_gate(space, history, seed=3, follow=steps.append)  # the default budget, 200 x 15
    found, found_energy, evaluations = gate.check(far.copy(), float(energy(far)[0]), 100, 2, history, energy)
    step = np.linalg.norm(found[T] - history[1][T])
    assert step <= root_step_limit(1, FPS) + 1e-9
    assert np.linalg.norm(found[T] - near[T]) < 0.05  # the near minimum (the jump was 1.5 m), found again
    # the search moves the arm towards the near minimum's: the prediction, its arm not moved, scores
    # 5 + 4 x (0.15 / 5 degrees)^2 = 16.9
    assert found_energy == pytest.approx(float(energy(found)[0])) and found_energy < 15.0
    assert evaluations > 100 + 200 * 15  # the re-search's budget counted
    assert len(gate.gated) == 1 and gate.gated[0]["frame"] == 2
    assert gate.gated[0]["speed_m_per_s"] == pytest.approx(np.linalg.norm(far[T] - history[1][T]) * FPS, abs=1e-3)
    assert gate.gated[0]["kept_speed_m_per_s"] <= gate.gated[0]["limit_m_per_s"]
    assert len(steps) == 1 and np.allclose(steps[0], found - far)
    assert gate.last_frame == 2


def test_a_polished_research_stays_within_the_bound():
    """The local fit after the re-search may pull the root back towards the far minimum: it is held on the bound."""
    space = make_space()
    history = walking_history()
    near = 2 * history[1] - history[0]
    far = near.copy()
    far[T] += [1.5, 0.0, 0.0]
    energy = two_basins(near, far)
    gate = tracking_gate(space, history, seed=1, polish=lambda pose: far.copy(), particles=60, iterations=6)
    found, _, _ = gate.check(far.copy(), 0.0, 0, 2, history, energy)
    assert np.linalg.norm(found[T] - history[1][T]) <= root_step_limit(1, FPS) + 1e-9


def test_a_fast_but_possible_move_passes_untouched():
    """7.5 m/s on the first step after the initial frame (which may correct the placement) and a move over three
    frames that is fast only per frame: nothing is searched, the estimate is returned as it came."""
    space = make_space()
    history = walking_history()

    def never(X):
        raise AssertionError("the gate searched a possible move")

    gate = tracking_gate(space, history, follow=lambda step: never(None))
    fast = history[1].copy()
    fast[T] += [0.25, 0.0, 0.0]  # 7.5 m/s at 30 fps
    got = gate.check(fast, 2.0, 7, 2, history, never)
    assert got[0] is fast and got[1:] == (2.0, 7)
    far = history[1].copy()
    far[T] += [0.9, 0.0, 0.0]  # 0.9 m in 3 frames: 9 m/s
    got = gate.check(far, 2.0, 7, 5, [history[0], fast], never)
    assert got[0] is far and gate.gated == []


def test_the_first_tracked_step_may_correct_the_placement():
    """The first frame after the initial one may move the root FIRST_STEP_SLACK further (the initial estimate can
    be as far off as the placement); the same step later is refused. The slack is kept across a checkpoint."""
    space = make_space()
    history = walking_history()
    step = history[1].copy()
    step[T] += [root_step_limit(1, FPS) + FIRST_STEP_SLACK / 2, 0.0, 0.0]

    def flat(X):
        return np.zeros(len(X))

    gate = RootGate(space, T, R, FPS, particles=20, iterations=2)
    gate.start(1)
    again = RootGate(space, T, R, FPS)
    again.restore(gate.state())
    for g in (gate, again):
        assert g.check(step, 0.0, 0, 2, history, flat)[0] is step and g.gated == []
        held = g.check(step + (step - history[1]), 0.0, 0, 3, [history[1], step], flat)[0]
        assert np.linalg.norm(held[T] - step[T]) <= root_step_limit(1, FPS) + 1e-9
        assert [x["frame"] for x in g.gated] == [3]
    old = RootGate(space, T, R, FPS)
    old.restore(None)  # a checkpoint from before the gate
    assert old.last_frame is None and not old.first_step


def test_without_a_history_the_first_frame_only_starts_the_gate():
    gate = RootGate(make_space(), T, R, FPS)
    x = np.zeros(D)
    assert gate.check(x, 1.0, 1, 4, [], None)[0] is x and gate.last_frame == 4


def test_the_tracker_refuses_a_jump_of_its_search(monkeypatch):
    """Wired into the tracker (walk scene): the search's estimate of frame 1 is moved 1.5 m; the tracker refuses it,
    searches again and lands near the truth; report data and checkpoint state say so."""
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses, scene_dir

    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.tracking.motion_library import build_motion_models, scene_exclusion
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.core.tracking.tracker import Tracker

    body, _, gt, _ = ground_truth_poses("walk")
    capture = load_capture(scene_dir("walk"))
    try:
        prior, dynamics = build_motion_models(body, fps=capture.frames.fps, exclude=scene_exclusion(scene_dir("walk")))
        # without the local fit, which would pull a moved root back onto the person before the gate sees it
        tracker = Tracker(body, capture, TrackingSettings(particles=60, iterations=5, prefetch=False, refine="none"),
                          prior=prior, dynamics=dynamics)
        search = tracker.optimizer.track_frame

        def jumped(energy, history):
            result = search(energy, history)
            estimate = result.estimate.copy()
            estimate[body.translation_dofs] += [1.2, 0.9, 0.0]
            return dataclasses.replace(result, estimate=estimate)

        monkeypatch.setattr(tracker.optimizer, "track_frame", jumped)
        tracker.initialise(0, initial_pose=gt[0])
        est = tracker.track(1, next_frame=None)
    finally:
        capture.close()
    hips_error = np.linalg.norm(est.pose[body.translation_dofs] - gt[1][body.translation_dofs])
    assert hips_error < 0.06, f"hips {hips_error:.3f} m from the truth after the re-search"
    assert [g["frame"] for g in tracker.gated] == [1] and tracker.gated[0]["speed_m_per_s"] > 40
    gate_state = tracker.state()["root_gate"]
    assert gate_state["last_frame"] == 1 and not gate_state["first_step"] and gate_state["velocity"] is None
    assert gate_state["track"][-1][0] == 1
    np.testing.assert_allclose(gate_state["track"][-1][1], est.pose[body.translation_dofs])
