"""Blender <-> engine: armature + skinned mesh -> core Body; DOF vectors -> pose-bone keys.

The only place that translates between Blender data and the engine's plain arrays
(cameras: see camera_bridge.py).
"""
import numpy as np

from ..core.body.model import Skeleton, build_body
from ..core.body.rig_checks import require_person_height, require_skin_weights, standing_height
from ..core.errors import InputError


class SubjectError(InputError):
    """The scene does not hold a usable armature + skinned mesh."""


def scene_armatures(scene):
    """The scene's armature objects, by name."""
    return sorted((o for o in scene.objects if o.type == "ARMATURE"), key=lambda o: o.name)


def ticked_armatures(scene):
    """The scene's armatures ticked as actors (Object.mocap_actor: the Subject panel's tick under 'Track Every
    Armature'), by name."""
    return [o for o in scene_armatures(scene) if o.mocap_actor]


def find_armature(scene, name=None):
    if name:
        obj = scene.objects.get(name)
        if obj is None or obj.type != "ARMATURE":
            raise SubjectError(f"no armature named {name!r} in scene {scene.name!r}")
        return obj
    arms = [o for o in scene.objects if o.type == "ARMATURE"]
    if len(arms) != 1:
        found = ", ".join(o.name for o in arms) or "none"
        raise SubjectError(f"expected exactly one armature in scene {scene.name!r} (found: {found}); "
                           f"name the one to track (--armature NAME, or pick it in the Subject panel)")
    return arms[0]


def find_skinned_mesh(armature_obj, scene):
    meshes = [o for o in scene.objects if o.type == "MESH" and any(
        m.type == "ARMATURE" and m.object == armature_obj for m in o.modifiers)]
    if not meshes:
        raise SubjectError(f"no mesh is skinned to armature {armature_obj.name!r}: add an Armature modifier "
                           f"pointing at it (Ctrl+P > With Automatic Weights)")
    return max(meshes, key=lambda o: len(o.data.vertices))


def _user_dof_specs(armature_obj):
    """Bones whose rotation locks or Limit Rotation constraints the user set."""
    specs = {}
    for pb in armature_obj.pose.bones:
        limit = next((c for c in pb.constraints if c.type == "LIMIT_ROTATION" and not c.mute), None)
        locks = tuple(pb.lock_rotation)
        if limit is None and not any(locks):
            continue
        axes = {}
        for i, letter in enumerate("XYZ"):
            if locks[i]:
                continue
            bounds = None
            if limit is not None and getattr(limit, f"use_limit_{letter.lower()}"):
                bounds = (getattr(limit, f"min_{letter.lower()}"), getattr(limit, f"max_{letter.lower()}"))
            axes[letter] = bounds
        mode = pb.rotation_mode if pb.rotation_mode in {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"} else "XYZ"
        specs[pb.name] = {"order": mode, "axes": axes}
    return specs


def skeleton_from_armature(armature_obj):
    bones = armature_obj.data.bones
    names = [b.name for b in bones]
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[b.parent.name] if b.parent else -1 for b in bones])
    rest = np.array([np.array(b.matrix_local) for b in bones])
    return Skeleton(names, parents, rest, np.array(armature_obj.matrix_world))


def body_from_blender(armature_obj, mesh_obj=None, scene=None):
    """Build the engine's Body from an armature and the mesh skinned to it (rest pose)."""
    import bpy

    scene = scene or bpy.context.scene
    mesh_obj = mesh_obj or find_skinned_mesh(armature_obj, scene)
    skeleton = skeleton_from_armature(armature_obj)
    mesh = mesh_obj.data
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    to_arm = np.linalg.inv(np.array(armature_obj.matrix_world)) @ np.array(mesh_obj.matrix_world)
    vertices = co @ to_arm[:3, :3].T + to_arm[:3, 3]
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    faces = tris.reshape(-1, 3)
    deform_bone = {b.name: i for i, b in enumerate(armature_obj.data.bones) if b.use_deform}
    group_bone = {g.index: deform_bone[g.name] for g in mesh_obj.vertex_groups if g.name in deform_bone}
    weights = np.zeros((len(mesh.vertices), skeleton.n_bones))
    for v in mesh.vertices:
        for g in v.groups:
            b = group_bone.get(g.group)
            if b is not None:
                weights[v.index, b] += g.weight
    if not group_bone:
        raise SubjectError(f"mesh {mesh_obj.name!r} has no vertex groups named after deforming bones of "
                           f"{armature_obj.name!r}: skin it first (Ctrl+P > With Automatic Weights)")
    require_skin_weights(weights, mesh_obj.name, armature_obj.name)
    world = co @ np.array(mesh_obj.matrix_world)[:3, :3].T + np.array(mesh_obj.matrix_world)[:3, 3]
    require_person_height(standing_height(world), armature_obj.name, scene.unit_settings.scale_length)
    return build_body(skeleton, vertices, faces, weights, _user_dof_specs(armature_obj))


def _set_basis(pose_bone, matrix, previous_euler=None):
    from mathutils import Matrix

    m = Matrix(matrix.tolist())
    loc, rot, _ = m.decompose()
    pose_bone.location = loc
    if pose_bone.rotation_mode == "QUATERNION":
        q = rot
        if pose_bone.rotation_quaternion.dot(q) < 0:  # keep keys on one hemisphere: no flips
            q = -q
        pose_bone.rotation_quaternion = q
    elif pose_bone.rotation_mode == "AXIS_ANGLE":
        axis, angle = rot.to_axis_angle()
        pose_bone.rotation_axis_angle = (angle, *axis)
    else:
        pose_bone.rotation_euler = rot.to_euler(pose_bone.rotation_mode, pose_bone.rotation_euler)


def driven_bones(body):
    """Bones the DOF vector moves (root + every DOF target)."""
    bones = {body.root_bone}
    for dof in body.dofs:
        bones.update(t.bone for t in dof.targets)
    return sorted(bones)


def apply_pose(armature_obj, body, pose, root_anchor=None):
    """Set the pose bones' transforms from one DOF vector (no keys)."""
    bases = body.local_bases(np.asarray(pose)[None], root_anchor)[0]
    names = body.skeleton.bone_names
    for b in driven_bones(body):
        _set_basis(armature_obj.pose.bones[names[b]], bases[b])


def key_pose(armature_obj, body, pose, frame, root_anchor=None):
    """Set and keyframe one DOF vector at `frame` on the driven bones."""
    apply_pose(armature_obj, body, pose, root_anchor)
    names = body.skeleton.bone_names
    for b in driven_bones(body):
        pb = armature_obj.pose.bones[names[b]]
        if b == body.root_bone:
            pb.keyframe_insert("location", frame=frame, group=pb.name)
        path = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}.get(
            pb.rotation_mode, "rotation_euler")
        pb.keyframe_insert(path, frame=frame, group=pb.name)


def evaluated_world_vertices(context, mesh_obj):
    """(V,3) world positions of a mesh's vertices as Blender evaluates them now (modifiers, armature)."""
    evaluated = mesh_obj.evaluated_get(context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        M = np.array(evaluated.matrix_world)
        return co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    finally:
        evaluated.to_mesh_clear()


def blender_joint_positions(armature_obj):
    """(B,3) world head positions as Blender evaluates them (bone order of the armature data)."""
    A = np.array(armature_obj.matrix_world)
    heads = np.array([np.array(pb.head) for pb in armature_obj.pose.bones])
    order = {pb.name: i for i, pb in enumerate(armature_obj.pose.bones)}
    heads = heads[[order[b.name] for b in armature_obj.data.bones]]
    return heads @ A[:3, :3].T + A[:3, 3]
