"""Helpers for tests on the bundled sample scenes: subject body, capture, ground-truth poses."""
from functools import lru_cache
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "sample_scenes"


def scene_dir(name="walk"):
    return SCENES / name


def cli_environment():
    """The environment for `python -m markerless_mocap ...` in a subprocess: the package importable as the tests
    import it, whatever the clone's folder is called."""
    import os

    import markerless_mocap

    env = dict(os.environ)
    package_parent = str(Path(markerless_mocap.__path__[0]).parent)  # where `markerless_mocap` imports from
    env["PYTHONPATH"] = os.pathsep.join([package_parent, env.get("PYTHONPATH", "")])
    return env


def track_refused_before_tracking(out, capsys, *options):
    """`track` on walk frames 0-3 with `options`: asserts it exits 2 before writing a frame; returns its stderr."""
    from markerless_mocap.operators.cli import main

    code = main(["track", "--scene", str(scene_dir("walk") / "subject.blend"), "--capture", str(scene_dir("walk")),
                 "--out", str(out), "--frames", "0-3", *options])
    assert code == 2
    assert not (Path(out) / "poses.npz").exists()
    return capsys.readouterr().err


def load_scene_body(bpy, name="walk"):
    """(body, armature object) of the scene's subject.blend."""
    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature

    bpy.ops.wm.open_mainfile(filepath=str(scene_dir(name) / "subject.blend"))
    arm = find_armature(bpy.context.scene)
    return body_from_blender(arm, None, bpy.context.scene), arm


@lru_cache(maxsize=4)
def ground_truth_poses(name="walk"):
    """Ground-truth joints as DOF vectors of the subject (fitted to every bone head; angles the heads
    do not see, such as the neck twist, held at rest)."""
    import bpy

    from markerless_mocap.core.body.pose_fit import poses_from_joints
    from markerless_mocap.core.results.result_folder import load_joints

    body, _ = load_scene_body(bpy, name)
    names, frames, positions = load_joints(scene_dir(name) / "gt_joints.npz")
    poses, residual = poses_from_joints(body, names, positions)
    return body, frames, poses, residual


def mean_joint_error(body, poses, truth_poses):
    a = body.joint_positions(np.atleast_2d(poses))
    b = body.joint_positions(np.atleast_2d(truth_poses))
    return float(np.linalg.norm(a - b, axis=-1).mean())


def walk_with_another_person():
    """Walk's actor at frame 30, where its tracker expects it (frame 29), and another person close by (frame 12's
    pose 0.45 m / 0.25 m away): (body, cameras, rig points, truth, predicted, points(pose) -> (C,K,2) capture pixels
    of the rig points, the other person's (C,K,2))."""
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.keypoints import rig_keypoints

    body, _, poses, _ = ground_truth_poses("walk")
    cameras = load_capture(scene_dir("walk")).cameras
    rig = rig_keypoints(body)
    truth, predicted = poses[30], poses[29]
    other = poses[12].copy()
    other[body.translation_dofs[:2]] = truth[body.translation_dofs[:2]] + [0.45, 0.25]

    def points(pose):
        world = rig.world(body, pose[None])[0]
        return np.stack([cam.project(world) for cam in cameras])

    return body, cameras, rig, truth, predicted, points, points(other)
