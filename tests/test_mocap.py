"""Motion readers and retargeting, checked against known FK results and against each other."""
from pathlib import Path

import numpy as np
import pytest

from markerless_mocap.core.mocap import (MotionClip, MotionFileError, RetargetError, cmu_name_map, euler_matrix,
                                         read_asf_amc, read_bvh, retarget)
from markerless_mocap.core.mocap.retarget import CMU_NAME_TABLE, Y_UP_TO_Z_UP, rotation_between

DATA = Path(__file__).parent / "data"
BVH_01 = DATA / "cmu_01_01_first31.bvh"
BVH_131 = DATA / "cmu_131_01_first12.bvh"
ASF_01, AMC_01 = DATA / "cmu_01.asf", DATA / "cmu_01_01_first30.amc"

# BVH joint -> the ASF bone that starts at the same point (the same CMU trial, two formats)
BVH_TO_ASF = {
    "Hips": "root", "LHipJoint": "lhipjoint", "LeftUpLeg": "lfemur", "LeftLeg": "ltibia", "LeftFoot": "lfoot",
    "LeftToeBase": "ltoes", "RHipJoint": "rhipjoint", "RightUpLeg": "rfemur", "RightLeg": "rtibia",
    "RightFoot": "rfoot", "RightToeBase": "rtoes", "LowerBack": "lowerback", "Spine": "upperback",
    "Spine1": "thorax", "Neck": "lowerneck", "Neck1": "upperneck", "Head": "head", "LeftShoulder": "lclavicle",
    "LeftArm": "lhumerus", "LeftForeArm": "lradius", "LeftHand": "lwrist", "LeftFingerBase": "lhand",
    "LFingers": "lfingers", "LThumb": "lthumb", "RightShoulder": "rclavicle", "RightArm": "rhumerus",
    "RightForeArm": "rradius", "RightHand": "rwrist", "RightFingerBase": "rhand", "RFingers": "rfingers",
    "RThumb": "rthumb",
}
# the BVH conversion leaves out two ASF segments: thorax (Neck and the collars sit on Spine1) and
# the wrist (FingerBase and Thumb sit on Hand)
DROPPED = {"Neck": "thorax", "LeftShoulder": "thorax", "RightShoulder": "thorax",
           "LeftFingerBase": "lwrist", "LThumb": "lwrist", "RightFingerBase": "rwrist", "RThumb": "rwrist"}


@pytest.fixture(scope="module")
def bvh01():
    return read_bvh(BVH_01)


@pytest.fixture(scope="module")
def amc01():
    return read_asf_amc(ASF_01, AMC_01)


def test_bvh_header_facts(bvh01):
    assert bvh01.n_joints == 31 and bvh01.n_frames == 31
    assert bvh01.fps == 120.0
    assert bvh01.units_to_metres == pytest.approx(0.0254 / 0.45)   # guessed: CMU units
    assert bvh01.joint_names[:3] == ["Hips", "LHipJoint", "LeftUpLeg"]
    np.testing.assert_allclose(bvh01.offsets[2], [1.36306, -1.79463, 0.83929])
    np.testing.assert_allclose(bvh01.root_positions[1], [9.37216, 17.8693, -17.3198], atol=2e-4)


def test_asf_amc_reproduces_bvh_of_the_same_trial(bvh01, amc01):
    """Same CMU trial in two formats: every segment vector agrees to well under a millimetre;
    the two segments the BVH conversion drops show up as exactly their ASF length."""
    assert amc01.n_frames == 30 and amc01.units_to_metres == pytest.approx(0.0254 / 0.45)
    pb = bvh01.world_positions(np.arange(1, 31), metres=True)     # BVH frame 0 is a T-pose
    pa = amc01.world_positions(np.arange(0, 30), metres=True)
    # length of a dropped ASF segment = the rest offset of its child (thorax -> lowerneck, wrist -> hand)
    seg_child = {"thorax": "lowerneck", "lwrist": "lhand", "rwrist": "rhand"}
    checked = 0
    for jb, name in enumerate(bvh01.joint_names):
        ja = amc01.index(BVH_TO_ASF[name])
        pbj, paj = bvh01.parents[jb], amc01.parents[ja]
        if pbj < 0:
            np.testing.assert_allclose(pb[:, jb], pa[:, ja], atol=1e-5)   # BVH rounds to 1e-4 units
            continue
        vb = pb[:, jb] - pb[:, pbj]
        va = pa[:, ja] - pa[:, paj]
        gap = np.linalg.norm(vb - va, axis=-1)
        if name in DROPPED:
            expected = np.linalg.norm(amc01.offsets[amc01.index(seg_child[DROPPED[name]])])
            assert expected > 1.0     # a real segment (CMU units), not a zero-length link
            np.testing.assert_allclose(gap, expected * amc01.units_to_metres, rtol=1e-3)
        else:
            assert gap.max() < 1e-4, (name, gap.max())
            checked += 1
    assert checked >= 22
    # the legs and spine are the same chain in both files: absolute positions agree too
    for name in ("LeftToeBase", "RightToeBase", "Spine1", "LeftFoot"):
        d = np.linalg.norm(pb[:, bvh01.index(name)] - pa[:, amc01.index(BVH_TO_ASF[name])], axis=-1)
        assert d.max() < 1e-4


def test_asf_rest_pose_frames(amc01):
    T = amc01.world_transforms([0])
    assert T.shape == (1, 31, 4, 4)
    R = T[0, :, :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.tile(np.eye(3), (31, 1, 1)), atol=1e-9)
    # with all motion zero, joint frames are the ASF axis frames
    rest = MotionClip(amc01.joint_names, amc01.parents, amc01.offsets, amc01.rest_rotations,
                      np.tile(np.eye(3), (1, 31, 1, 1)), np.zeros((1, 3)), 120.0)
    np.testing.assert_allclose(rest.world_transforms()[0, :, :3, :3], amc01.rest_rotations, atol=1e-12)
    # lfemur axis "0 0 20 XYZ" is a 20 degree turn about Z
    np.testing.assert_allclose(amc01.rest_rotations[amc01.index("lfemur")], euler_matrix("Z", [20.0]), atol=1e-12)


TINY = """HIERARCHY
ROOT Root
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {root_order}
  JOINT A
  {{
    OFFSET 0 1 0
    CHANNELS 3 {a_order}
    End Site
    {{
      OFFSET 0 0 1
    }}
  }}
}}
MOTION
Frames: {n}
Frame Time: 0.5
{frames}
"""


def _tiny(tmp_path, root_order, a_order, frames):
    p = tmp_path / "tiny.bvh"
    p.write_text(TINY.format(root_order=root_order, a_order=a_order, n=len(frames),
                             frames="\n".join(" ".join(str(v) for v in f) for f in frames)))
    return p


def _end_site(clip, f=0):
    T = clip.world_transforms([f])[0]
    return T[1, :3, 3] + T[1, :3, :3] @ clip.end_sites[1]


def test_tiny_bvh_channel_orders(tmp_path):
    # A: X 90 then Y 90 -> R = Rx(90) Ry(90): (0,0,1) -> Ry -> (1,0,0) -> Rx -> (1,0,0)
    clip = read_bvh(_tiny(tmp_path, "Zrotation Xrotation Yrotation", "Xrotation Yrotation Zrotation",
                          [[0, 0, 0, 0, 0, 0, 90, 90, 0]]), units_to_metres=1.0)
    np.testing.assert_allclose(clip.world_positions()[0, 1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(_end_site(clip), [1, 1, 0], atol=1e-12)
    # same angles, order Z X Y on A with Z=0: Rx(90) Ry(90) again
    clip = read_bvh(_tiny(tmp_path, "Zrotation Xrotation Yrotation", "Zrotation Xrotation Yrotation",
                          [[0, 0, 0, 0, 0, 0, 0, 90, 90]]), units_to_metres=1.0)
    np.testing.assert_allclose(_end_site(clip), [1, 1, 0], atol=1e-12)
    # Y first then X: R = Ry(90) Rx(90): (0,0,1) -> (0,-1,0) -> (0,-1,0)
    clip = read_bvh(_tiny(tmp_path, "Zrotation Xrotation Yrotation", "Yrotation Xrotation Zrotation",
                          [[0, 0, 0, 0, 0, 0, 90, 90, 0]]), units_to_metres=1.0)
    np.testing.assert_allclose(_end_site(clip), [0, 0, 0], atol=1e-12)


def test_tiny_bvh_root_motion_and_rotation(tmp_path):
    # root at (2,3,4) turned 90 degrees about Z: A's offset (0,1,0) -> (-1,0,0)
    clip = read_bvh(_tiny(tmp_path, "Zrotation Xrotation Yrotation", "Zrotation Xrotation Yrotation",
                          [[2, 3, 4, 90, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0, 0, 0]]), units_to_metres=1.0)
    P = clip.world_positions()
    np.testing.assert_allclose(P[0, 0], [2, 3, 4], atol=1e-12)
    np.testing.assert_allclose(P[0, 1], [1, 3, 4], atol=1e-12)
    np.testing.assert_allclose(_end_site(clip, 0), [1, 3, 5], atol=1e-12)
    np.testing.assert_allclose(P[1], [[0, 0, 0], [0, 1, 0]], atol=1e-12)
    assert clip.fps == 2.0


def test_euler_matrix_matches_scipy():
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(0)
    ang = rng.uniform(-180, 180, size=(20, 3))
    for order in ("ZYX", "XYZ", "ZXY", "YXZ"):
        ref = Rotation.from_euler(order, ang, degrees=True).as_matrix()   # upper case = intrinsic
        np.testing.assert_allclose(euler_matrix(order, ang), ref, atol=1e-12)


def test_resample_exact_and_slerp(bvh01):
    half = bvh01.resample(30)
    assert half.fps == 30 and half.n_frames == 8          # frames 0,4,...,28 of 31
    np.testing.assert_array_equal(half.local_rotations, bvh01.local_rotations[::4])
    np.testing.assert_array_equal(half.root_positions, bvh01.root_positions[::4])
    # a quarter turn about Z between two frames: the midpoint is the eighth turn
    two = MotionClip(["r"], [-1], np.zeros((1, 3)), np.eye(3)[None],
                     np.stack([euler_matrix("Z", [0.0]), euler_matrix("Z", [90.0])])[:, None],
                     np.array([[0.0, 0, 0], [2.0, 0, 0]]), fps=1.0)
    up = two.resample(2.0)
    assert up.n_frames == 3
    np.testing.assert_allclose(up.local_rotations[1, 0], euler_matrix("Z", [45.0]), atol=1e-12)
    np.testing.assert_allclose(up.root_positions[1], [1.0, 0, 0])


def test_bad_files_say_what_is_wrong(tmp_path):
    with pytest.raises(FileNotFoundError, match="BVH file not found"):
        read_bvh(tmp_path / "missing.bvh")
    p = tmp_path / "cut.bvh"
    p.write_text(BVH_01.read_text()[:3000])
    with pytest.raises(MotionFileError, match="cut.bvh"):
        read_bvh(p)
    p.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 1 Wobble\n}\n")
    with pytest.raises(ValueError, match="unknown channel"):
        read_bvh(p)
    amc = tmp_path / "bad.amc"
    amc.write_text(":FULLY-SPECIFIED\n1\nroot 0 0 0 0 0 0\nnosuchbone 1 2 3\n")
    with pytest.raises(MotionFileError, match="nosuchbone"):
        read_asf_amc(ASF_01, amc)


# ------------------------------------------------------------------------------ retargeting
def _armature_from_clip(clip, bend_arms_deg=0.0):
    """A Blender-style target built from the source skeleton itself (Z-up, metres, bone Y along the
    segment). bend_arms_deg turns both arm chains down about the shoulder (an A-pose)."""
    C = Y_UP_TO_Z_UP
    Q = clip.rest_positions() @ C.T * clip.units_to_metres
    children = [[c for c, p in enumerate(clip.parents) if p == j] for j in range(clip.n_joints)]

    def direction(j):
        for c in children[j]:
            stack = [c]
            while stack:
                k = stack.pop(0)
                v = Q[k] - Q[j]
                if np.linalg.norm(v) > 1e-6:
                    return v
                stack += children[k]
        if j in clip.end_sites:
            return C @ clip.end_sites[j]
        return np.array([0.0, 0.0, 1.0])

    heads, rest = Q.copy(), np.zeros((clip.n_joints, 4, 4))
    for j in range(clip.n_joints):
        y = direction(j)
        y = y / np.linalg.norm(y)
        x = np.cross(y, [0.3, 0.5, 0.8])
        x /= np.linalg.norm(x)
        rest[j, :3, :3] = np.stack([x, y, np.cross(x, y)], axis=1)
        rest[j, :3, 3] = heads[j]
        rest[j, 3, 3] = 1.0
    if bend_arms_deg:
        for side, sign in (("LeftArm", -1.0), ("RightArm", 1.0)):
            s = clip.index(side)
            Rb = euler_matrix("Y", [sign * -bend_arms_deg])   # about the forward axis (-Y is front)
            pivot = heads[s].copy()
            for j in range(clip.n_joints):
                k = j
                while k >= 0 and k != s:
                    k = clip.parents[k]
                if k == s:
                    rest[j, :3, :3] = Rb @ rest[j, :3, :3]
                    rest[j, :3, 3] = pivot + Rb @ (rest[j, :3, 3] - pivot)
    return rest


def test_retarget_onto_own_skeleton_reproduces_the_motion(bvh01):
    rest = _armature_from_clip(bvh01)
    names = list(bvh01.joint_names)
    res = retarget(bvh01, rest, bvh01.parents, names, name_map={n: n for n in names}, root_scale=1.0)
    ref = bvh01.world_positions(metres=True) @ Y_UP_TO_Z_UP.T
    np.testing.assert_allclose(res.world_alignment, Y_UP_TO_Z_UP, atol=1e-12)
    np.testing.assert_allclose(res.head_positions(), ref, atol=1e-9)


def test_retarget_a_pose_target_follows_source_directions(bvh01):
    rest = _armature_from_clip(bvh01, bend_arms_deg=45.0)
    names = list(bvh01.joint_names)
    res = retarget(bvh01, rest, bvh01.parents, names, name_map={n: n for n in names}, root_scale=1.0)
    ref = bvh01.world_positions(metres=True) @ Y_UP_TO_Z_UP.T
    # bones keep their lengths, so positions still match: the 45-degree A-pose rest is undone
    np.testing.assert_allclose(res.head_positions(), ref, atol=1e-9)
    # the rest pose of the arm is visibly different: the basis rotations are not those of the T-pose
    plain = retarget(bvh01, _armature_from_clip(bvh01), bvh01.parents, names,
                     name_map={n: n for n in names}, root_scale=1.0)
    la = names.index("LeftArm")
    assert np.abs(res.basis_rotations[:, la] - plain.basis_rotations[:, la]).max() > 0.3


def test_retarget_unmapped_bone_stays_at_rest(bvh01):
    rest = _armature_from_clip(bvh01)
    names = list(bvh01.joint_names)
    m = {n: n for n in names if n != "LeftForeArm"}
    res = retarget(bvh01, rest, bvh01.parents, names, name_map=m, root_scale=1.0)
    np.testing.assert_allclose(res.basis_rotations[:, names.index("LeftForeArm")],
                               np.tile(np.eye(3), (bvh01.n_frames, 1, 1)), atol=1e-12)


def test_blender_pose_composition_from_basis(bvh01):
    """pose = parent_pose @ (parent_rest^-1 @ rest) @ basis, recomputed independently."""
    rest = _armature_from_clip(bvh01, bend_arms_deg=30.0)
    names = list(bvh01.joint_names)
    res = retarget(bvh01, rest, bvh01.parents, names, name_map={n: n for n in names}, root_scale=1.0)
    f = 7
    pose = {}
    for b, p in enumerate(bvh01.parents):
        basis = np.eye(4)
        basis[:3, :3] = res.basis_rotations[f, b]
        if p < 0:
            basis[:3, 3] = res.root_location[f]
            pose[b] = rest[b] @ basis
        else:
            pose[b] = pose[p] @ np.linalg.inv(rest[p]) @ rest[b] @ basis
        np.testing.assert_allclose(pose[b], res.pose_matrices[f, b], atol=1e-9)


def test_cmu_name_table_covers_both_namings():
    mb = read_bvh(BVH_01)
    old = read_bvh(BVH_131)
    # 31 rig bones; the rigid pelvis links LHipJoint/RHipJoint are deliberately unmapped
    assert len(CMU_NAME_TABLE) == 29
    assert len({row[0] for row in CMU_NAME_TABLE}) == 29
    m_mb, m_old = cmu_name_map(mb.joint_names), cmu_name_map(old.joint_names)
    assert len(m_mb) == 29 and len(m_old) == 29
    assert set(m_mb.values()) <= set(mb.joint_names) and set(m_old.values()) <= set(old.joint_names)
    assert m_old["LeftUpLeg"] == "LeftHip" and m_old["Spine1"] == "Chest2" and m_old["Neck1"] == "Neck"
    assert m_mb["LeftHandFinger1"] == "LFingers"
    with pytest.raises(RetargetError, match="name_map"):
        cmu_name_map(["a", "b"])


def test_retarget_rejects_bad_maps(bvh01):
    rest = _armature_from_clip(bvh01)
    names = list(bvh01.joint_names)
    with pytest.raises(RetargetError, match="NoSuchJoint"):
        retarget(bvh01, rest, bvh01.parents, names, name_map={"Hips": "NoSuchJoint"})


def test_rotation_between_is_minimal():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        R = rotation_between(a, b)
        np.testing.assert_allclose(R @ (a / np.linalg.norm(a)), b / np.linalg.norm(b), atol=1e-12)
        axis = np.cross(a, b)
        np.testing.assert_allclose(R @ axis, axis, atol=1e-9)      # turns about a x b only
    R = rotation_between(np.array([0, 0, 1.0]), np.array([0, 0, -1.0]))
    np.testing.assert_allclose(R @ [0, 0, 1.0], [0, 0, -1.0], atol=1e-12)
