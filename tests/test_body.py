"""Body model: FK + LBS against Blender's own deformation, rig mapping, anatomy of the DOF axes."""
import numpy as np
import pytest

from markerless_mocap.core.body.model import Skeleton, build_body
from markerless_mocap.core.body.proxy import make_proxy
from markerless_mocap.core.body.rig_presets import RigMappingError

from rig_helpers import build_armature, load_subject

bpy = pytest.importorskip("bpy")


def _bridge():
    from markerless_mocap.addon import scene_bridge

    return scene_bridge


def random_poses(body, rng, n, spread=0.3):
    lo = np.where(np.isfinite(body.lower), body.lower, -np.pi / 3)
    hi = np.where(np.isfinite(body.upper), body.upper, np.pi / 3)
    x = rng.uniform(lo, hi, size=(n, body.n_dof))
    x[:, body.translation_dofs] = body.default_pose()[body.translation_dofs] + rng.normal(0, spread, (n, 3))
    return x


def evaluated_world_vertices(mesh_obj):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = mesh_obj.evaluated_get(dg).data
    co = np.empty(len(ev.vertices) * 3)
    ev.vertices.foreach_get("co", co)
    M = np.array(mesh_obj.matrix_world)
    return co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]


@pytest.fixture
def subject(bpy_module):
    arm, mesh = load_subject(bpy_module)
    # A non-trivial object transform: the engine must work in world space like Blender does.
    arm.location = (0.4, -0.3, 0.05)
    arm.rotation_euler = (0.0, 0.0, 0.6)
    bpy.context.view_layer.update()
    body = _bridge().body_from_blender(arm, mesh, bpy.context.scene)
    return arm, mesh, body


def test_subject_maps_to_30_dof(subject):
    _, _, body = subject
    assert body.preset == "cmu"
    assert body.n_dof == 30
    groups = {g: len(ix) for g, ix in body.prior_groups.items()}
    assert groups == {"upper": 11, "head": 3, "lower": 10}


def test_fk_lbs_matches_blender_depsgraph(subject):
    arm, mesh, body = subject
    rng = np.random.default_rng(7)
    poses = random_poses(body, rng, 6)
    ours = body.deform(poses)  # batched, all poses in one call
    for x, verts in zip(poses, ours):
        _bridge().apply_pose(arm, body, x)
        bpy.context.view_layer.update()
        theirs = evaluated_world_vertices(mesh)
        assert np.abs(theirs - verts).max() < 1e-4


def test_batch_equals_single_calls(subject):
    _, _, body = subject
    poses = random_poses(body, np.random.default_rng(1), 5)
    batch = body.joint_positions(poses)
    single = np.stack([body.joint_positions(x[None])[0] for x in poses])
    assert np.allclose(batch, single, atol=1e-12)


def test_local_bases_equal_the_product_of_each_dof_rotation(subject):
    # local_bases makes every DOF rotation in one batched call; the reference multiplies them bone by bone.
    from markerless_mocap.core.body.rotations import axis_angle_matrix

    _, _, body = subject
    poses = random_poses(body, np.random.default_rng(3), 7)
    reference = np.broadcast_to(np.eye(4), (7, body.skeleton.n_bones, 4, 4)).copy()
    for b, dofs in enumerate(body.bone_dofs):
        for i, axis, share in dofs:
            reference[:, b, :3, :3] = reference[:, b, :3, :3] @ axis_angle_matrix(axis, poses[:, i] * share)
    reference[:, body.root_bone] = body._root_basis(poses, None)
    np.testing.assert_allclose(body.local_bases(poses), reference, rtol=0, atol=1e-15)


def test_numba_kinematics_equal_the_numpy_reference(subject):
    from markerless_mocap.core.body import kinematics_fast as fast_kinematics

    _, _, body = subject
    rng = np.random.default_rng(11)
    poses = random_poses(body, rng, 25, spread=1.0)
    anchor = rng.normal(size=(3, 3))
    anchor = np.linalg.qr(anchor)[0] * np.sign(np.linalg.det(np.linalg.qr(anchor)[0]))  # a rotation
    for root_anchor in (None, anchor):
        for world in (True, False):
            ref = body.pose_matrices_reference(poses, root_anchor, world)
            fast = fast_kinematics.pose_matrices(body, poses, body._root_basis(poses, root_anchor), world)
            np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12)
            np.testing.assert_allclose(body.pose_matrices(poses, root_anchor, world), ref, rtol=0, atol=1e-12)
    # One pose, as the local fit asks.
    np.testing.assert_allclose(body.pose_matrices(poses[3]), body.pose_matrices_reference(poses[3]), rtol=0, atol=1e-12)


def test_numba_skinning_equals_the_numpy_reference(subject):
    from markerless_mocap.core.body.model import blend_vertices
    from markerless_mocap.core.body.skinning_fast import blend_vertices as fast_blend

    _, _, body = subject
    proxy = make_proxy(body, 2000)
    M = body.skinning_matrices(random_poses(body, np.random.default_rng(4), 9))
    for verts, weights, unweighted in [(body.vertices, body.weights, body.unweighted),
                                       (proxy.vertices, proxy.weights, proxy.unweighted)]:
        unweighted = unweighted.copy()
        unweighted[::97] = True  # vertices no bone moves stay put, in both
        weights = np.where(unweighted[:, None], 0.0, weights)
        ref = blend_vertices(M, verts, weights, unweighted, body.skeleton.armature_matrix)
        np.testing.assert_allclose(fast_blend(M, verts, weights, unweighted, body.skeleton.armature_matrix), ref,
                                   rtol=0, atol=1e-12)


def test_keyed_pose_reads_back_same_joints(subject):
    arm, _, body = subject
    bridge = _bridge()
    arm.pose.bones["LeftArm"].rotation_mode = "XYZ"  # Euler and quaternion bones both round-trip
    poses = random_poses(body, np.random.default_rng(3), 3)
    for frame, x in enumerate(poses, start=1):
        bridge.key_pose(arm, body, x, frame)
    for frame, x in enumerate(poses, start=1):
        bpy.context.scene.frame_set(frame)
        assert np.abs(bridge.blender_joint_positions(arm) - body.joint_positions(x[None])[0]).max() < 1e-5


def test_default_pose_is_rest(subject):
    _, _, body = subject
    joints = body.joint_positions(body.default_pose()[None])[0]
    assert np.abs(joints - body.skeleton.rest_heads_world()).max() < 1e-6  # float32 rest data


def _dof(body, name):
    return body.dof_names.index(name)


def _joint(body, x, bone):
    return body.joint_positions(x[None])[0, body.skeleton.index[bone]]


# The CMU-named MakeHuman rig renamed to Rigify's deform-bone names (same geometry, other naming).
RIGIFY_NAMES = {"Hips": "DEF-spine", "LowerBack": "DEF-spine.001", "Spine": "DEF-spine.002",
                "Spine1": "DEF-spine.003", "Neck": "DEF-spine.004", "Neck1": "DEF-spine.005", "Head": "DEF-spine.006",
                **{f"{side}{cmu}": f"DEF-{rigify}.{side[0]}" for side in ("Left", "Right") for cmu, rigify in
                   (("Arm", "upper_arm"), ("ForeArm", "forearm"), ("Hand", "hand"), ("UpLeg", "thigh"),
                    ("Leg", "shin"), ("Foot", "foot"))}}


def _rename_to_rigify(arm):
    for bone in arm.data.bones:
        if bone.name in RIGIFY_NAMES:
            bone.name = RIGIFY_NAMES[bone.name]


@pytest.mark.parametrize("rig_file,prefix", [("cmu_mb_rest.json", ""), ("mixamo_rest.json", "mixamorig:"),
                                             ("cmu_mb_rest.json", "rigify")])
def test_anatomical_axes_bend_the_right_way(bpy_module, rig_file, prefix):
    """Positive flexion moves limbs the anatomical way, whatever the bones' roll (CMU, Mixamo, Rigify)."""
    arm = build_armature(bpy_module, rig_file)
    names = {}
    if prefix == "rigify":
        _rename_to_rigify(arm)
        names, prefix = RIGIFY_NAMES, ""
    skeleton = _bridge().skeleton_from_armature(arm)
    body = build_body(skeleton, np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, skeleton.n_bones)))
    assert body.n_dof == 30
    assert body.preset == ("rigify" if names else "mixamo" if prefix else "cmu")
    forward, left = np.array([0, -1.0, 0]), np.array([1.0, 0, 0])  # MakeHuman faces -Y, left is +X
    x0 = body.default_pose()

    def moved(dof, bone, angle):
        x = x0.copy()
        x[_dof(body, dof)] = np.deg2rad(angle)
        bone = names.get(bone, prefix + bone)
        return _joint(body, x, bone) - _joint(body, x0, bone)

    assert moved("l_knee.flex", "LeftFoot", 60) @ forward < -0.1  # foot goes back
    assert moved("r_knee.flex", "RightFoot", 60) @ forward < -0.1
    assert moved("l_hip.flex", "LeftLeg", 45) @ forward > 0.1  # knee goes forward
    assert moved("r_hip.flex", "RightLeg", 45) @ forward > 0.1
    assert moved("l_hip.abd", "LeftLeg", 30) @ left > 0.05  # left knee goes out to the left
    assert moved("r_hip.abd", "RightLeg", 30) @ left < -0.05
    assert moved("l_shoulder.flex", "LeftForeArm", 60) @ forward > 0.1  # elbow goes forward
    assert moved("l_elbow.flex", "LeftHand", 60) @ forward > 0.05  # hand comes forward and up
    assert moved("spine.flex", "Neck" if not prefix else "Neck", 30) @ forward > 0.05


def test_unmappable_rig_names_missing_bones():
    names = ["pelvis", "LeftArm", "LeftForeArm"]
    skeleton = Skeleton(names, np.array([-1, 0, 1]), np.tile(np.eye(4), (3, 1, 1)))
    with pytest.raises(RigMappingError) as err:
        build_body(skeleton, np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, 3)))
    message = str(err.value)
    assert "Hips" in message and "RightUpLeg" in message and "missing bones" in message


def test_rotation_locks_and_limit_constraint_define_the_dof(subject):
    arm, mesh, _ = subject
    knee = arm.pose.bones["LeftLeg"]
    knee.lock_rotation = (False, True, True)
    limit = knee.constraints.new("LIMIT_ROTATION")
    limit.use_limit_x, limit.min_x, limit.max_x = True, -0.1, 2.2
    body = _bridge().body_from_blender(arm, mesh, bpy.context.scene)
    knee_dofs = [d for d in body.dofs if any(body.skeleton.bone_names[t.bone] == "LeftLeg" for t in d.targets)]
    assert [d.name for d in knee_dofs] == ["LeftLeg.rotx"]
    assert (knee_dofs[0].lower, knee_dofs[0].upper) == pytest.approx((-0.1, 2.2))
    # The keyed value turns the bone about its local X exactly as Blender's Euler X does.
    x = body.default_pose()
    x[body.dof_names.index("LeftLeg.rotx")] = 0.8
    _bridge().apply_pose(arm, body, x)
    assert tuple(knee.rotation_quaternion.to_euler("XYZ")) == pytest.approx((0.8, 0, 0), abs=1e-6)


def test_proxy_mesh_is_close_to_the_full_mesh(subject):
    _, _, body = subject
    proxy = make_proxy(body, target_triangles=2000)
    assert abs(len(proxy.faces) - 2000) <= 200
    assert set(np.unique(proxy.face_part)) == set(range(len(body.part_names)))
    assert proxy.part_area_share.sum() == pytest.approx(1.0)
    from scipy.spatial import cKDTree

    pose = random_poses(body, np.random.default_rng(5), 1)
    full = body.deform(pose)[0]
    coarse = proxy.deform(body, pose)[0]
    dist, _ = cKDTree(full).query(coarse)
    assert np.median(dist) < 0.01 and dist.max() < 0.05


def test_pose_fit_recovers_heads_and_holds_unseen_angles(subject):
    """Fitting DOFs to bone heads alone: the heads come back, and the neck twist, which barely moves
    a head, stays at rest with the hold term instead of chasing the noise (it reached its limit on the
    sample scenes' ground truth before)."""
    from markerless_mocap.core.body.pose_fit import fit_pose_sequence

    _, _, body = subject
    rng = np.random.default_rng(5)
    twist = body.dof_names.index("neck.twist")
    truth = body.default_pose() + np.cumsum(rng.normal(0, 0.06, (8, body.n_dof)), axis=0)  # a smooth motion
    truth[:, twist] = 0.0
    truth = body.clamp(truth)
    heads = body.joint_positions(truth)
    noisy = heads + rng.normal(0, 0.003, heads.shape)  # motion capture is a few millimetres off
    start = body.default_pose()
    poses, residual = fit_pose_sequence(body, noisy, x0=start, hold_weight=0.01)
    fitted = body.joint_positions(poses)
    print("max head error (mm):", np.abs(fitted - heads).max() * 1000, "neck twist:", poses[:, twist])
    assert np.abs(fitted - heads).max() < 0.01
    assert residual.max() < 0.005
    assert np.abs(poses[:, twist]).max() < 0.05


def test_single_rotation_fast_path_equals_the_batched_formula():
    """skew and axis_angle_matrix take a literal / scalar path for one vector and one angle (the local fit
    calls them per DOF): the same matrices as the batched path."""
    from markerless_mocap.core.body.rotations import axis_angle_matrix, skew

    rng = np.random.default_rng(3)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = float(rng.uniform(-3.0, 3.0))
        v = rng.normal(size=3)
        assert np.allclose(skew(axis) @ v, np.cross(axis, v), atol=1e-12)
        assert np.allclose(skew(axis), skew(axis[None])[0], atol=0)
        assert np.allclose(axis_angle_matrix(axis, angle), axis_angle_matrix(axis, np.array([angle]))[0], atol=1e-14)
