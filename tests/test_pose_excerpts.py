"""The pose excerpts that widen the anatomical prior (core/data/poses): intact, from no reserved subject, mapped
onto the rig within its joint limits, and reaching poses the two walking/jumping clips never show."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from markerless_mocap.core.mocap.bvh import read_bvh
from markerless_mocap.core.tracking.motion_library import POSES_DIR

EXCERPTS = sorted(POSES_DIR.glob("*.bvh"))
RESERVED_SUBJECTS = {"05", "11", "13", "14", "131"}  # their trials make the evaluation scenes (SOURCE.txt)
BODY_JOINTS_MAX_STEP_DEG = 25.0  # the fastest real step between two 120 fps frames here is 17 degrees (a kick's foot)


def _frame_rows(path):
    motion = path.read_text().split("Frame Time:")[1].splitlines()[1:]
    return [line.split() for line in motion if line.strip()]


def test_every_excerpt_is_whole_and_its_consecutive_frames_move_like_a_body():
    """Each file parses, holds 24 frames of 96 numbers, and each pair of consecutive frames (1/120 s apart) turns
    no body joint by more than a real motion does: a number copied wrong tears its pair apart."""
    assert len(EXCERPTS) >= 16
    for path in EXCERPTS:
        assert path.stem.split("_")[0].lstrip("0") not in {s.lstrip("0") for s in RESERVED_SUBJECTS}, path.name
        clip = read_bvh(path)
        rows = _frame_rows(path)
        assert len(rows) == 24 and all(len(r) == 96 for r in rows), path.name
        values = np.array(rows, dtype=float)
        euler = values[:, 3:].reshape(len(values), -1, 3)
        mats = Rotation.from_euler("ZYX", euler.reshape(-1, 3), degrees=True).as_matrix()
        mats = mats.reshape(*euler.shape[:2], 3, 3)
        relative = np.einsum("fjab,fjac->fjbc", mats[0::2], mats[1::2])
        step = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=2, axis2=3) - 1) / 2, -1, 1)))
        body_joints = [i for i, n in enumerate(clip.joint_names) if "Thumb" not in n and "Index" not in n
                       and "FingerBase" not in n]  # the hands' markers jitter; the 30-DOF body has no fingers
        assert step[:, body_joints].max() < BODY_JOINTS_MAX_STEP_DEG, (path.name, step[:, body_joints].max())
        root_step_m = np.abs(values[0::2, :3] - values[1::2, :3]).max() * 0.0564  # CMU units
        assert root_step_m < 0.1, (path.name, root_step_m)  # 12 m/s


def test_excerpts_map_onto_the_rig_within_its_limits_and_reach_beyond_the_clips(tmp_path, monkeypatch):
    pytest.importorskip("bpy")
    from scene_helpers import ground_truth_poses, scene_dir

    from markerless_mocap.core.tracking.motion_library import excerpt_poses, scene_exclusion, training_sequences

    monkeypatch.setenv("MOCAP_CACHE_DIR", str(tmp_path))
    body, _, _, _ = ground_truth_poses("walk")
    poses = excerpt_poses(body)
    assert poses.shape == (24 * len(EXCERPTS), body.n_dof) and np.all(np.isfinite(poses))
    joints = slice(6, None)
    assert np.all(poses[:, joints] >= body.lower[joints] - 1e-9)
    assert np.all(poses[:, joints] <= body.upper[joints] + 1e-9)
    clips = np.concatenate(training_sequences(body, exclude=scene_exclusion(scene_dir("walk"))))
    dof = {n: i for i, n in enumerate(body.dof_names)}
    for name in ("l_shoulder.flex", "r_shoulder.flex", "l_hip.flex", "r_hip.flex", "l_knee.flex"):
        # arms raised overhead, a thigh lifted high, a deep knee bend: what dance, sport and getting up add
        assert poses[:, dof[name]].max() > clips[:, dof[name]].max() + np.deg2rad(15), name
    assert np.array_equal(excerpt_poses(body), poses)  # the cache returns the same poses
