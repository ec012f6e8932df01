"""Smoothing of a finished take (core/tracking/smoothing.py): the filter's measured response, the root orientation
through 180 degrees, gaps and short runs, joint limits, a cut-off the frame rate cannot carry, and a tracked
take that is keyed, exported and saved smoothed with the solved poses kept, and smoothed again with another
cut-off from the command line and from the Track panel without tracking again."""
from types import SimpleNamespace

import numpy as np
import pytest

from markerless_mocap.core.body.rotations import rotvec_to_matrix
from markerless_mocap.core.tracking.smoothing import (MIN_RUN, SmoothingError, check_cutoff, consecutive_runs,
                                                      smooth_poses)

FPS = 30.0


def _body(n_dof, rotation=(), lower=-np.inf, upper=np.inf):
    return SimpleNamespace(root_rotation_dofs=np.array(rotation, dtype=np.int64),
                           lower=np.full(n_dof, lower, dtype=float), upper=np.full(n_dof, upper, dtype=float))


def _amplitude(signal, hz, t):
    """Amplitude of the `hz` component of `signal` over times t (a whole number of periods)."""
    return 2 * abs(np.mean(signal * np.exp(-2j * np.pi * hz * t)))


def test_motion_passes_jitter_is_removed_and_nothing_lags():
    t = np.arange(150) / FPS
    motion = 0.4 * np.sin(2 * np.pi * 1.5 * t)  # a limb swinging at a walk's 1.5 Hz
    jitter = np.random.default_rng(0).normal(0, 0.03, t.size)
    out = smooth_poses(_body(1), (motion + jitter)[:, None], np.arange(t.size), FPS, 8.0)[:, 0]
    inner = slice(15, -15)  # away from the ends' padding
    assert _amplitude(out[inner], 1.5, t[inner]) == pytest.approx(0.4, rel=0.02)
    # white jitter keeps about the pass band's share of its power (8 of 15 Hz): its rms drops by ~sqrt(2)
    residual = np.sqrt(np.mean((out - motion)[inner] ** 2))
    assert residual < 0.75 * 0.03
    lags = np.arange(-5, 6)
    corr = [np.dot(np.roll(out, k)[inner], motion[inner]) for k in lags]
    assert lags[int(np.argmax(corr))] == 0


def test_a_component_at_the_cutoff_keeps_half_its_amplitude():
    # 2nd-order Butterworth: |H|^2 = 1/2 at the cut-off; forwards and backwards: |H|^2 overall
    t = np.arange(300) / FPS
    inner = slice(30, -30)

    def gain(hz, cutoff):
        out = smooth_poses(_body(1), np.sin(2 * np.pi * hz * t)[:, None], np.arange(t.size), FPS, cutoff)[:, 0]
        return _amplitude(out[inner], hz, t[inner])

    assert gain(4.0, 4.0) == pytest.approx(0.5, abs=0.02)
    assert gain(8.0, 8.0) == pytest.approx(0.5, abs=0.02)
    # above the cut-off: a digital Butterworth's |H|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi fc / fs))^(2 order))
    warped = np.tan(np.pi * 7 / FPS) / np.tan(np.pi * 4 / FPS)
    assert gain(7.0, 4.0) == pytest.approx(1 / (1 + warped ** 4), abs=0.005)
    assert gain(1.0, 8.0) == pytest.approx(1.0, abs=0.01)


def test_root_orientation_turning_through_180_degrees_stays_smooth():
    # A turn from 150 to 210 degrees about Z: the rotation vector as solved jumps from +pi to -pi halfway.
    yaw = np.deg2rad(np.linspace(150, 210, 40))
    poses = np.zeros((40, 6))  # three translations, then the root's rotation vector
    poses[:, 5] = (yaw + np.pi) % (2 * np.pi) - np.pi
    out = smooth_poses(_body(6, rotation=(3, 4, 5)), poses, np.arange(40), FPS, 6.0)
    R_in, R_out = rotvec_to_matrix(poses[:, 3:]), rotvec_to_matrix(out[:, 3:])
    cos = (np.einsum("fij,fij->f", R_in, R_out) - 1) / 2
    assert np.rad2deg(np.arccos(np.clip(cos, -1, 1))).max() < 0.5  # a steady turn passes unchanged
    # each smoothed rotation vector is the one of its pair nearest to the solved one: the DOF values jump
    # where the solved ones do, nowhere else
    assert np.abs(out[:, 5] - poses[:, 5]).max() < np.deg2rad(0.5)


def test_gaps_split_the_take_and_short_runs_stay_as_solved():
    frames = np.r_[np.arange(0, 20), np.arange(40, 40 + MIN_RUN - 1)]
    poses = np.r_[np.zeros(20), np.ones(MIN_RUN - 1)][:, None]
    poses[5] = 0.3  # one jittered frame in the first run
    out = smooth_poses(_body(1), poses, frames, FPS, 6.0)
    assert consecutive_runs(frames) == [(0, 20), (20, 20 + MIN_RUN - 1)]
    np.testing.assert_array_equal(out[20:], poses[20:])  # too short to filter
    assert abs(out[5, 0]) < 0.15 and abs(out[19, 0]) < 0.01  # smoothed; the later frames' 1 does not leak in


def test_joint_angles_stay_within_their_limits():
    rng = np.random.default_rng(1)
    poses = np.clip(1.0 + rng.normal(0, 0.2, (60, 2)), -1.2, 1.2)  # jitter at the joint's upper limit
    out = smooth_poses(_body(2, lower=-1.2, upper=1.2), poses, np.arange(60), FPS, 5.0)
    assert out.max() <= 1.2 and out.min() >= -1.2


def test_a_cutoff_the_frame_rate_cannot_carry_is_refused():
    assert check_cutoff(8.0, 30.0) == pytest.approx(8.0 / 15.0)
    with pytest.raises(SmoothingError, match=r"15 Hz at 30 fps.*choose less than 15 Hz, or 0"):
        check_cutoff(15.0, 30.0)
    with pytest.raises(SmoothingError, match="positive"):
        check_cutoff(-1.0, 30.0)


def test_track_refuses_a_cutoff_above_the_footage_limit_before_tracking(tmp_path, capsys):
    pytest.importorskip("bpy")
    from scene_helpers import track_refused_before_tracking

    err = track_refused_before_tracking(tmp_path / "out", capsys, "--smooth", "20")
    assert "smoothing cut-off 20 Hz is not below half the frame rate (15 Hz at 30 fps)" in err


def test_a_tracked_take_is_smoothed_keyed_and_the_solved_poses_are_kept(tmp_path):
    bpy = pytest.importorskip("bpy")
    import json

    from scene_helpers import scene_dir

    from markerless_mocap.addon.scene_bridge import blender_joint_positions, body_from_blender, find_armature
    from markerless_mocap.operators.cli import main

    out = tmp_path / "out"
    code = main(["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(scene_dir("walk")),
                 "--out", str(out), "--frames", "0-9", "--particles", "10", "--iterations", "2",
                 "--likelihood", "silh+edge", "--no-overlays", "--smooth", "6", "--no-foot-lock"])
    assert code == 0
    joints, raw = np.load(out / "joints.npz"), np.load(out / "joints_raw.npz")
    poses, poses_raw = np.load(out / "poses.npz"), np.load(out / "poses_raw.npz")
    scene = bpy.context.scene
    arm = find_armature(scene)
    body = body_from_blender(arm, None, scene)
    expected = smooth_poses(body, poses_raw["poses"], poses_raw["frames"], FPS, 6.0)
    np.testing.assert_allclose(poses["poses"], expected, atol=1e-12)
    np.testing.assert_allclose(joints["positions"], body.joint_positions(expected), atol=1e-9)
    moved = np.abs(joints["positions"] - raw["positions"]).max()
    assert moved > 1e-4  # smoothing changed the take ...
    names = [str(n) for n in joints["names"]]
    order = [names.index(b.name) for b in arm.data.bones]
    for k, frame in enumerate(joints["frames"]):  # ... and the armature is keyed with the smoothed take
        scene.frame_set(int(frame) + scene.frame_start)
        np.testing.assert_allclose(blender_joint_positions(arm), joints["positions"][k][order], atol=1e-4)
    report = json.loads((out / "report.json").read_text())
    assert report["smoothing"]["cutoff_hz"] == 6.0
    assert (out / "animation.bvh").is_file() and (out / "tracked.blend").is_file()

    # Another cut-off without tracking again: resume the finished take; 0 gives back the solved poses.
    args = ["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(scene_dir("walk")),
            "--out", str(out), "--frames", "0-9", "--particles", "10", "--iterations", "2", "--likelihood",
            "silh+edge", "--no-overlays", "--resume", "--no-foot-lock"]
    assert main(args + ["--smooth", "3"]) == 0
    np.testing.assert_allclose(np.load(out / "poses.npz")["poses"],
                               smooth_poses(body, poses_raw["poses"], poses_raw["frames"], FPS, 3.0), atol=1e-12)
    np.testing.assert_array_equal(np.load(out / "poses_raw.npz")["poses"], poses_raw["poses"])
    assert main(args + ["--smooth", "0"]) == 0
    np.testing.assert_array_equal(np.load(out / "poses.npz")["poses"], poses_raw["poses"])
    np.testing.assert_array_equal(np.load(out / "joints.npz")["positions"], raw["positions"])
    assert not (out / "poses_raw.npz").exists() and not (out / "joints_raw.npz").exists()
    assert "smoothing" not in json.loads((out / "report.json").read_text())


def test_the_track_panel_resmooths_a_finished_take_with_its_new_cutoff(addon_module_name, bpy_module, tmp_path):
    """Track panel: *Resume* on a finished output folder with another *Smoothing* value smooths the solved
    take again (the same finish as `track --resume --smooth`), keys it and says so, without tracking again."""
    from scene_helpers import scene_dir

    from markerless_mocap.addon.scene_bridge import blender_joint_positions, body_from_blender, find_armature

    bpy = bpy_module
    walk = scene_dir("walk")
    bpy.ops.wm.open_mainfile(filepath=str(walk / "subject.blend"))
    m = bpy.context.scene.mocap
    out = tmp_path / "out"
    m.capture_dir, m.output_dir = str(walk), str(out)
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 7
    m.likelihood, m.particles, m.iterations, m.smoothing_hz = "silh+edge", 10, 2, 6.0
    m.foot_lock = False  # smoothing alone (foot locking: tests/test_foot_contact.py)
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert "smoothed at 6 Hz" in m.status
    raw = np.load(out / "poses_raw.npz")

    m.resume, m.smoothing_hz = True, 3.0
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert m.status == "All 8 frames were already tracked; the take smoothed again at 3 Hz"
    scene = bpy.context.scene
    arm = find_armature(scene)
    body = body_from_blender(arm, None, scene)
    expected = smooth_poses(body, raw["poses"], raw["frames"], FPS, 3.0)
    np.testing.assert_allclose(np.load(out / "poses.npz")["poses"], expected, atol=1e-12)
    np.testing.assert_array_equal(np.load(out / "poses_raw.npz")["poses"], raw["poses"])  # not solved again
    joints = np.load(out / "joints.npz")
    names = [str(n) for n in joints["names"]]
    order = [names.index(b.name) for b in arm.data.bones]
    for k, frame in enumerate(joints["frames"]):
        scene.frame_set(int(frame) + scene.frame_start)
        np.testing.assert_allclose(blender_joint_positions(arm), body.joint_positions(expected[k:k + 1])[0][order],
                                   atol=1e-4)
    m.smoothing_hz = 0.0  # and back to the solved poses
    assert bpy.ops.mocap.track() == {"FINISHED"}
    assert m.status == "All 8 frames were already tracked; the take rewritten as solved (no smoothing)"
    np.testing.assert_array_equal(np.load(out / "poses.npz")["poses"], raw["poses"])
