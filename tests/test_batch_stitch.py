"""Stitching chunks (core/batch/stitch.py) on a small synthetic body: the cross-fade starts and ends on the two
chunks' poses with no step, the root and every bone turn along the shortest arc (a bone turning about several axes
is not an interpolation of its angles), and the overlap's disagreement is reported as it is."""
import numpy as np
import pytest

from markerless_mocap.core.batch.chunk_folder import ChunkError
from markerless_mocap.core.batch.plan import plan_chunks
from markerless_mocap.core.batch.stitch import blend_poses, stitch
from markerless_mocap.core.body.model import Body, Dof, DofTarget, Skeleton
from markerless_mocap.core.body.rotations import matrix_to_rotvec, rotvec_to_matrix
from markerless_mocap.core.tracking.settings import FrameEstimate


def _rest(y):
    m = np.eye(4)
    m[1, 3] = y
    return m


def _body():
    """A chain of three bones: the root (translation + rotation vector), a ball joint turning about three axes
    (x, then z, then y as the tracker's Euler-like DOF do), and a hinge."""
    skeleton = Skeleton(["root", "ball", "hinge", "tip"], np.array([-1, 0, 1, 2]),
                        np.stack([_rest(0.0), _rest(0.5), _rest(0.9), _rest(1.2)]))
    dofs = [Dof(f"root.t{a}", "translation", -np.inf, np.inf, "root") for a in "xyz"]
    dofs += [Dof(f"root.r{a}", "root_rotation", -np.inf, np.inf, "root") for a in "xyz"]
    dofs += [Dof(f"ball.{a}", "angle", -3.0, 3.0, "ball", "", [DofTarget(1, np.eye(3)[i], 1.0)])
             for a, i in (("x", 0), ("z", 2), ("y", 1))]
    dofs += [Dof("hinge.flex", "angle", -0.1, 2.5, "hinge", "", [DofTarget(2, np.array([1.0, 0, 0]), 1.0)])]
    return Body(skeleton, dofs, np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, 4)), 0)


A = np.array([0.1, 0.0, 0.9, 0.2, -0.4, 1.0, 0.6, -0.5, 0.3, 0.4])
B = np.array([0.3, 0.1, 1.0, -0.3, 0.2, 2.6, -0.2, 0.7, -0.6, 1.3])


def _bone(body, pose, bone):
    return body.local_bases(pose[None])[0, bone, :3, :3]


def _angle(r1, r2):
    return float(np.linalg.norm(matrix_to_rotvec(r1.T @ r2)))


def test_the_ends_are_the_two_poses_and_the_fade_has_no_step():
    body = _body()
    assert np.allclose(blend_poses(body, A, B, 0.0), A) and np.allclose(blend_poses(body, A, B, 1.0), B)
    ts = np.linspace(0, 1, 41)
    joints = np.array([body.joint_positions(blend_poses(body, A, B, t)[None])[0] for t in ts])
    steps = np.linalg.norm(np.diff(joints, axis=0), axis=-1).max(axis=1)
    assert steps.max() < 2.5 * np.median(steps)  # no jump anywhere along the fade, the ends included
    near = blend_poses(body, A, B, 1e-4)
    assert np.abs(near - A).max() < 1e-3


def test_root_and_bones_turn_along_the_shortest_arc():
    body = _body()
    for t in (0.25, 0.5, 0.8):
        x = blend_poses(body, A, B, t)
        ra, rb, rt = rotvec_to_matrix(A[3:6]), rotvec_to_matrix(B[3:6]), rotvec_to_matrix(x[3:6])
        whole = _angle(ra, rb)
        assert _angle(ra, rt) == pytest.approx(t * whole, abs=1e-9)
        assert _angle(rt, rb) == pytest.approx((1 - t) * whole, abs=1e-9)
        for bone in (1, 2):
            ba, bb, bt = _bone(body, A, bone), _bone(body, B, bone), _bone(body, x, bone)
            whole = _angle(ba, bb)
            assert _angle(ba, bt) == pytest.approx(t * whole, abs=1e-5)
            assert _angle(bt, bb) == pytest.approx((1 - t) * whole, abs=1e-5)
        assert x[9] == pytest.approx((1 - t) * A[9] + t * B[9])  # a hinge's arc is its angle's line
        assert np.allclose(x[:3], (1 - t) * A[:3] + t * B[:3])
    # the ball joint's angles blended as numbers leave the arc: the fit is needed
    linear = (A + B) / 2
    ba, bb = _bone(body, A, 1), _bone(body, B, 1)
    assert abs(_angle(ba, _bone(body, linear, 1)) - _angle(_bone(body, linear, 1), bb)) > 0.01


def test_the_root_rotation_vector_stays_continuous_past_half_a_turn():
    """A root near 180 degrees: the blended rotation vector is the one nearest the two chunks', not its twin."""
    body = _body()
    a, b = A.copy(), A.copy()
    a[3:6] = [0, 0, np.pi - 0.05]
    b[3:6] = [0, 0, -(np.pi - 0.05)]  # 0.1 rad further on, written the other way round
    x = blend_poses(body, a, b, 0.5)
    assert _angle(rotvec_to_matrix(x[3:6]), rotvec_to_matrix(a[3:6])) == pytest.approx(0.05, abs=1e-9)


def _estimates(body, frames, offset):
    """A chunk's solved frames: a smooth motion, shifted by `offset` (how this chunk disagrees with the truth)."""
    out = {}
    for f in frames:
        pose = A + (B - A) * f / 40.0 + offset
        out[f] = FrameEstimate(f, pose, body.joint_positions(pose[None])[0], 0.1, 1.0, 10)
    return out


def test_stitch_keeps_each_frame_once_fades_without_a_step_and_reports_the_overlap():
    body = _body()
    plan = plan_chunks(0, 39, 14, 4, 4)
    offsets = [np.zeros(10), np.r_[0.02, 0, 0, 0, 0, 0, 0, 0, 0, 0], np.zeros(10)]  # chunk 1 sits 20 mm aside
    chunks = [_estimates(body, range(c.track[0], c.track[1] + 1), o) for c, o in zip(plan, offsets)]
    stitched, overlaps = stitch(body, plan, chunks)
    assert [e.frame for e in stitched] == list(range(40))
    joints = np.array([e.joints for e in stitched])
    unbroken = np.array([e.joints for e in _estimates(body, range(40), 0).values()])
    extra = np.linalg.norm(np.diff(joints - unbroken, axis=0), axis=-1).max(axis=1)
    # 20 mm spread over the 4 faded frames' 5 steps: 4 mm more per step, never the whole 20 mm at once
    assert extra.max() == pytest.approx(0.02 / 5, abs=1e-6)
    assert [o["mean_joint_mm"] for o in overlaps] == pytest.approx([20.0, 20.0])
    assert overlaps[0]["frames"] == [plan[1].keep[0], plan[1].keep[0] + 3]
    assert overlaps[0]["shared"]["mean_joint_mm"] == pytest.approx([20.0] * len(overlaps[0]["shared"]
                                                                                   ["mean_joint_mm"]))
    outside = [e for e in stitched if plan[1].keep[0] + 4 <= e.frame <= plan[1].keep[1]]
    assert all(np.allclose(e.pose, chunks[1][e.frame].pose) for e in outside)  # beyond the fade: as solved


def test_a_chunk_missing_frames_is_named():
    body = _body()
    plan = plan_chunks(0, 19, 10, 2, 2)
    chunks = [_estimates(body, range(c.track[0], c.track[1] + 1), 0) for c in plan]
    del chunks[1][15]
    with pytest.raises(ChunkError, match="chunk 1 .*lacks frames 15-15"):
        stitch(body, plan, chunks)


def test_the_chunks_reports_are_carried_frame_by_frame_from_the_chunk_that_keeps_the_frame():
    from markerless_mocap.core.batch.stitch_report import per_frame_facts

    plan = plan_chunks(0, 29, 10, 3, 2)   # tracked 0-11, 7-21, 17-29; kept 0-9, 10-19, 20-29
    assert [c.keep for c in plan] == [(0, 9), (10, 19), (20, 29)]
    reports = [
        {"views_shared": {"4": ["cam2"], "11": ["cam1"]},          # frame 11: chunk 0's overlap, not kept
         "landmarks_set_aside": {"9": {"cam1": 2}, "10": {"cam3": 1}},
         "limb_recoveries": [{"frame": 5, "limbs": ["l_arm"], "kept": True}]},
        {"views_shared": {"8": ["cam4"], "12": ["cam2", "cam3"]},  # frame 8: chunk 1's warm-up, not kept
         "landmarks_set_aside": {"10": {"cam1": 4}},
         "root_gate": [{"frame": 18, "speed_m_per_s": 30.0}, {"frame": 9, "speed_m_per_s": 12.0}]},
        {},                                                       # a chunk that recorded nothing
    ]
    facts = per_frame_facts(plan, reports)
    assert facts["views_shared"] == {"4": ["cam2"], "12": ["cam2", "cam3"]}
    assert facts["landmarks_set_aside"] == {"9": {"cam1": 2}, "10": {"cam1": 4}}
    assert facts["limb_recoveries"] == [{"frame": 5, "limbs": ["l_arm"], "kept": True}]
    assert facts["root_gate"] == [{"frame": 18, "speed_m_per_s": 30.0}]
    assert "views_left_out" not in facts
    assert per_frame_facts(plan, [{}, {}, {}]) == {}
