"""Test helpers: armatures built in bpy from the rest data in tests/data/rigs, and the sample subject."""
import json
import os
from pathlib import Path

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).resolve().parents[1]


def subject_blend_path():
    """The sample subject (override with MOCAP_TEST_SUBJECT to run the body tests on your own rig)."""
    override = os.environ.get("MOCAP_TEST_SUBJECT")
    return Path(override) if override else REPO / "sample_scenes" / "walk" / "subject.blend"


def build_armature(bpy, rig_file, name="Armature"):
    bones = json.loads((DATA / "rigs" / rig_file).read_text())["bones"]
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for bone_name, b in bones.items():
        eb = arm.edit_bones.new(bone_name)
        eb.head, eb.tail, eb.roll = b["head"], b["tail"], b["roll"]
    for bone_name, b in bones.items():
        if b["parent"]:
            arm.edit_bones[bone_name].parent = arm.edit_bones[b["parent"]]
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def load_subject(bpy):
    """Open the subject .blend; return (armature object, skinned mesh object)."""
    bpy.ops.wm.open_mainfile(filepath=str(subject_blend_path()))
    scene = bpy.context.scene
    arm = next(o for o in scene.objects if o.type == "ARMATURE")
    mesh = next(o for o in scene.objects if o.type == "MESH" and any(
        m.type == "ARMATURE" and m.object == arm for m in o.modifiers))
    return arm, mesh
