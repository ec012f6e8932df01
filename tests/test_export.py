"""FBX / BVH export round trips: every keyed frame comes back, no leaf bones, same bone motion.

A small skinned armature is keyed on 5 frames (some channels change linearly, which curve
simplification would thin out), exported with operators/export.py, and re-imported into a clean
scene with Blender's own importers. The motion is compared per frame and bone as the world-space
rotation since the rest pose (independent of how the importer orients bones) and as head positions.
"""
import importlib

import numpy as np
import pytest

pytestmark = pytest.mark.bpy

FRAMES = range(3, 8)
BONES = {  # name: (head, tail, parent)
    "hips": ((0.0, 0.0, 1.0), (0.0, 0.0, 1.2), None),
    "spine": ((0.0, 0.0, 1.2), (0.0, 0.05, 1.6), "hips"),
    "arm.L": ((0.1, 0.05, 1.55), (0.45, 0.05, 1.5), "spine"),
    "thigh.L": ((0.1, 0.0, 1.0), (0.12, -0.02, 0.55), "hips"),
}


def _euler(bone, frame):
    t = frame - FRAMES[0]
    return {"hips": (0.0, 0.0, 0.15 * t),  # linear: a simplifier would drop the middle keys
            "spine": (0.1 * np.sin(t), 0.05 * t, 0.0),
            "arm.L": (0.0, 0.3 * np.cos(0.7 * t), 0.2 + 0.1 * t * t),
            "thigh.L": (-0.2 * t, 0.0, 0.05 * np.sin(2 * t))}[bone]


def _build_keyed_subject(bpy):
    arm_data = bpy.data.armatures.new("Rig")
    arm = bpy.data.objects.new("Rig", arm_data)
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    for name, (head, tail, _) in BONES.items():
        eb = arm_data.edit_bones.new(name)
        eb.head, eb.tail = head, tail
    for name, (_, _, parent) in BONES.items():
        if parent:
            arm_data.edit_bones[name].parent = arm_data.edit_bones[parent]
    bpy.ops.object.mode_set(mode="OBJECT")

    # A mesh skinned to the armature (one box per bone, rigidly weighted).
    verts, faces, groups = [], [], []
    for name, (head, tail, _) in BONES.items():
        c = (np.array(head) + np.array(tail)) / 2
        base = len(verts)
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)
        verts += [tuple(c + 0.03 * np.array(s)) for s in corners]
        faces += [tuple(base + i for i in q) for q in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6),
                                                       (0, 2, 6, 4), (1, 5, 7, 3))]
        groups.append((name, range(base, base + 8)))
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(verts, [], faces)
    body = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(body)
    for name, idx in groups:
        body.vertex_groups.new(name=name).add(list(idx), 1.0, "REPLACE")
    body.modifiers.new("Armature", "ARMATURE").object = arm
    body.parent = arm

    arm.location = (0.3, -0.2, 0.0)
    for frame in FRAMES:
        for name in BONES:
            pb = arm.pose.bones[name]
            pb.rotation_mode = "XYZ"
            pb.rotation_euler = _euler(name, frame)
            pb.keyframe_insert("rotation_euler", frame=frame, group=name)
        root = arm.pose.bones["hips"]
        root.location = (0.02 * (frame - 3), 0.1 * np.sin(frame), 0.0)
        root.keyframe_insert("location", frame=frame, group="hips")
    return arm, body


def _unit_rotation(m):
    m = np.array(m)[:3, :3]
    return m / np.linalg.norm(m, axis=0)


def _motion(bpy, arm, frames, armature_space=False):
    """{frame: {bone: (world rotation since rest (3x3), world head (3,))}} (or in armature space)."""
    scene = bpy.context.scene
    out = {}
    for frame in frames:
        scene.frame_set(frame)
        world = np.eye(4) if armature_space else np.array(arm.matrix_world)
        per_bone = {}
        for name in BONES:
            pb, bone = arm.pose.bones[name], arm.data.bones[name]
            pose_w = _unit_rotation(world @ np.array(pb.matrix))
            rest_w = _unit_rotation(world @ np.array(bone.matrix_local))
            head = (world @ np.append(np.array(pb.head), 1.0))[:3]
            per_bone[name] = (pose_w @ rest_w.T, head)
        out[frame] = per_bone
    return out


def _assert_same_motion(expected, actual, head_tol=1e-4):
    assert sorted(actual) == sorted(expected)
    for frame, bones in expected.items():
        for name, (rot, head) in bones.items():
            rot2, head2 = actual[frame][name]
            cos = np.clip((np.trace(rot.T @ rot2) - 1) / 2, -1, 1)
            assert np.arccos(cos) < 1e-3, f"frame {frame} bone {name}: rotation differs by {np.arccos(cos):.2e} rad"
            np.testing.assert_allclose(head2, head, atol=head_tol, err_msg=f"frame {frame} bone {name}")


@pytest.fixture
def keyed(addon_module_name, bpy_module):
    arm, body = _build_keyed_subject(bpy_module)
    export = importlib.import_module(f"{addon_module_name}.operators.export")
    compat = importlib.import_module(f"{addon_module_name}.addon.anim_compat")
    return bpy_module, arm, export, compat


def _imported_armature(bpy):
    arms = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
    assert len(arms) == 1
    return arms[0]


def test_keyed_range_helper(keyed):
    bpy, arm, _, compat = keyed
    assert compat.keyed_frame_range(arm) == (FRAMES[0], FRAMES[-1])
    assert compat.keyed_frames(arm, 'pose.bones["hips"].location') == [float(f) for f in FRAMES]
    assert len(compat.object_fcurves(arm)) == 3 * len(BONES) + 3
    assert compat.keyed_frame_range(bpy.data.objects["Body"]) is None


def test_fbx_round_trip_keeps_every_frame_and_no_leaf_bones(keyed, tmp_path):
    bpy, arm, export, compat = keyed
    expected = _motion(bpy, arm, FRAMES)
    path = export.export_fbx(bpy.context, arm, tmp_path / "out" / "anim.fbx")
    assert path.is_file()
    assert bpy.context.scene.frame_start == 1  # the scene range is restored after the export

    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(path), anim_offset=0.0, automatic_bone_orientation=False)
    imported = _imported_armature(bpy)
    names = {b.name for b in imported.data.bones}
    assert names == set(BONES), f"leaf or missing bones: {sorted(names ^ set(BONES))}"
    assert any(o.type == "MESH" for o in bpy.context.scene.objects), "the skinned mesh was not exported"
    for name in BONES:  # every frame is a key on every bone: nothing simplified away
        assert compat.keyed_frames(imported, f'pose.bones["{name}"].rotation') == [float(f) for f in FRAMES]
    _assert_same_motion(expected, _motion(bpy, imported, FRAMES))


def test_bvh_round_trip(keyed, tmp_path):
    bpy, arm, export, compat = keyed
    # Blender's BVH exporter writes armature space (the object's transform is not part of the file).
    expected = _motion(bpy, arm, FRAMES, armature_space=True)
    assert "not part of the BVH" in export.bvh_transform_warning(arm)
    path = export.export_bvh(bpy.context, arm, tmp_path / "anim.bvh")
    text = path.read_text()
    assert f"Frames: {len(FRAMES)}" in text

    bpy.ops.wm.read_homefile(use_empty=True)
    # Blender's BVH exporter writes Blender axes (Z up), so import without an axis change.
    bpy.ops.import_anim.bvh(filepath=str(path), frame_start=FRAMES[0], axis_forward="Y", axis_up="Z",
                            update_scene_duration=True)
    imported = _imported_armature(bpy)
    assert {b.name for b in imported.data.bones} == set(BONES)
    assert compat.keyed_frame_range(imported) == (FRAMES[0], FRAMES[-1])
    assert np.allclose(np.array(imported.matrix_world), np.eye(4))
    _assert_same_motion(expected, _motion(bpy, imported, FRAMES))


def test_export_without_keys_names_the_fix(keyed, tmp_path):
    bpy, arm, export, _ = keyed
    arm.animation_data_clear()
    with pytest.raises(ValueError, match="no keyframes.*track it first"):
        export.export_bvh(bpy.context, arm, tmp_path / "x.bvh")
    with pytest.raises(ValueError, match="ends before it starts"):
        export.export_fbx(bpy.context, arm, tmp_path / "x.fbx", frame_range=(9, 4))


def test_export_operators(keyed, tmp_path):
    bpy, arm, _, _ = keyed
    bpy.context.scene.mocap.armature = arm
    assert bpy.ops.mocap.export_fbx(filepath=str(tmp_path / "a.fbx"), include_mesh=False) == {"FINISHED"}
    assert bpy.ops.mocap.export_bvh(filepath=str(tmp_path / "a.bvh")) == {"FINISHED"}
    assert (tmp_path / "a.fbx").stat().st_size > 0 and (tmp_path / "a.bvh").stat().st_size > 0
