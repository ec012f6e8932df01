"""Blender side of the actor calibration: a copy of the user's rig and mesh with the actor's proportions
applied, for inspection (the original is never touched). The engine computes the new bone heads and skin
(core.actor.proportions.scaled_body); this only writes them into Blender data."""
import numpy as np

from ..core.actor.proportions import bone_factors, scaled_body
from .scene_bridge import body_from_blender, find_skinned_mesh


def apply_proportions_to_copy(scene, armature_obj, proportions, suffix="_actor"):
    """Duplicate `armature_obj` and its skinned mesh, lengthen the copy's bones and move its skin by
    `proportions`; returns (armature copy, mesh copy), linked into `scene`'s collection of the original."""
    import bpy
    from mathutils import Vector

    mesh_obj = find_skinned_mesh(armature_obj, scene)
    body = body_from_blender(armature_obj, mesh_obj, scene)
    actor = scaled_body(body, proportions)
    own, _ = bone_factors(body.skeleton.bone_names, body.skeleton.parents, body.roles, proportions)

    arm_copy = armature_obj.copy()
    arm_copy.data = armature_obj.data.copy()
    arm_copy.animation_data_clear()
    arm_copy.name = armature_obj.name + suffix
    mesh_copy = mesh_obj.copy()
    mesh_copy.data = mesh_obj.data.copy()
    mesh_copy.name = mesh_obj.name + suffix
    collection = armature_obj.users_collection[0] if armature_obj.users_collection else scene.collection
    collection.objects.link(arm_copy)
    collection.objects.link(mesh_copy)
    for mod in mesh_copy.modifiers:
        if mod.type == "ARMATURE" and mod.object == armature_obj:
            mod.object = arm_copy
    if mesh_obj.parent == armature_obj:
        mesh_copy.parent = arm_copy

    # bones: heads from the engine, tails along the same direction scaled by the bone's own factor
    heads = {n: actor.skeleton.rest[i, :3, 3] for i, n in enumerate(body.skeleton.bone_names)}
    factor = dict(zip(body.skeleton.bone_names, own))
    view_layer = bpy.context.view_layer
    previous = view_layer.objects.active
    view_layer.objects.active = arm_copy
    bpy.ops.object.mode_set(mode="EDIT")
    edit = arm_copy.data.edit_bones
    old = {eb.name: (np.array(eb.head), np.array(eb.tail), eb.roll) for eb in edit}
    connected = {eb.name: eb.use_connect for eb in edit}
    for eb in edit:
        eb.use_connect = False  # move heads freely; reconnected below where they were connected
    for eb in edit:
        head, tail, roll = old[eb.name]
        eb.head = Vector(heads[eb.name].tolist())
        eb.tail = Vector((heads[eb.name] + factor[eb.name] * (tail - head)).tolist())
        eb.roll = roll
    for eb in edit:
        eb.use_connect = connected[eb.name]
    bpy.ops.object.mode_set(mode="OBJECT")
    view_layer.objects.active = previous

    # skin: the engine's vertices are in armature space; the mesh stores them in its own space
    to_mesh = np.linalg.inv(np.array(mesh_obj.matrix_world)) @ np.array(armature_obj.matrix_world)
    co = actor.vertices @ to_mesh[:3, :3].T + to_mesh[:3, 3]
    mesh_copy.data.vertices.foreach_set("co", co.ravel())
    mesh_copy.data.update()
    return arm_copy, mesh_copy
