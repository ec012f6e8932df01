"""A sample scene's subject as version-neutral plain data, and back to a .blend.

A .blend saved by Blender 5.0 does not open in 4.2-4.4 ("incomplete header, may be from a newer
version of Blender"), while a file saved by an older Blender opens in every newer one. So each sample
scene keeps `subject_source.json.gz` (armature, mesh, skin weights, materials, scene frame rate as
plain numbers) and its `subject.blend` is built from that source by the oldest Blender at hand
(Debian 13's 4.3.2, see tests/real_blender/stage.sh --resave-subjects):

    python tools/portable_subject.py dump SUBJECT.blend SOURCE.json.gz            (any bpy / blender)
    blender -b --factory-startup --python tools/portable_subject.py -- build SOURCE.json.gz SUBJECT.blend

Only what the sample subjects use is kept: the armatures (bones, rest pose, pose-bone rotation modes and
locks), the meshes skinned to each (vertices, faces, smooth flags, material slots, vertex groups, Armature
modifier, parenting) and node materials (node types, their settings, unlinked input values, links). A scene of
one armature is written as version 1 ("armature", "meshes"); one of several actors (sample_scenes/duet) as
version 2 ("subjects": a list of {"armature", "meshes"}), which a reader of version 1 refuses rather than
building only the first. Runs inside Blender's own Python: bpy and the standard library only.
"""
import gzip
import json
import sys

FORMAT = "markerless_mocap.portable_subject"
VERSION = 1
SEVERAL_VERSION = 2  # several armatures; the version-1 layout is kept for one, so those files do not change

# Node settings worth carrying (those that exist on the node in the running Blender are set).
_NODE_SETTINGS = ("blend_type", "use_clamp", "noise_dimensions", "noise_type", "normalize", "data_type",
                  "clamp_factor", "clamp_result", "factor_mode", "distribution", "subsurface_method",
                  "operation", "interpolation", "color_ramp_interpolation")


def _floats(seq):
    return [float(x) for x in seq]


def _matrix(m):
    return [_floats(row) for row in m]


def _transform(obj):
    return {"location": _floats(obj.location), "rotation_mode": obj.rotation_mode,
            "rotation_euler": _floats(obj.rotation_euler), "rotation_quaternion": _floats(obj.rotation_quaternion),
            "scale": _floats(obj.scale)}


def _socket_value(socket):
    if not hasattr(socket, "default_value"):
        return None
    value = socket.default_value
    if isinstance(value, (int, float, bool, str)):
        return value
    try:
        return [float(x) for x in value]
    except TypeError:
        return None


def dump_material(mat):
    out = {"name": mat.name, "diffuse_color": _floats(mat.diffuse_color), "roughness": float(mat.roughness),
           "metallic": float(mat.metallic), "nodes": [], "links": []}
    tree = mat.node_tree
    if tree is None:
        return out
    for node in tree.nodes:
        settings = {k: getattr(node, k) for k in _NODE_SETTINGS if hasattr(node, k)}
        inputs = {}
        for i, socket in enumerate(node.inputs):
            if socket.is_linked:
                continue
            value = _socket_value(socket)
            if value is not None:
                inputs[f"{i}:{socket.identifier}"] = value
        out["nodes"].append({"type": node.bl_idname, "name": node.name, "location": _floats(node.location),
                             "settings": settings, "inputs": inputs})
    for link in tree.links:
        out["links"].append({"from_node": link.from_node.name, "from_socket": link.from_socket.identifier,
                             "from_index": list(link.from_node.outputs).index(link.from_socket),
                             "to_node": link.to_node.name, "to_socket": link.to_socket.identifier,
                             "to_index": list(link.to_node.inputs).index(link.to_socket)})
    return out


def dump(scene=None):
    """The subjects of `scene` (its armatures and the meshes skinned to each) as plain data: version 1 for one
    armature, version 2 for several."""
    import bpy

    scene = scene or bpy.context.scene
    armatures = [o for o in scene.objects if o.type == "ARMATURE"]
    if not armatures:
        raise ValueError(f"no armature in scene {scene.name!r}")
    subjects = [_dump_subject(bpy, scene, arm) for arm in armatures]
    materials = {}
    for subject in subjects:
        for mesh in subject["meshes"]:
            for name in mesh["materials"]:
                if name and name not in materials:
                    materials[name] = dump_material(bpy.data.materials[name])
    head = {"format": FORMAT, "version": VERSION if len(subjects) == 1 else SEVERAL_VERSION,
            "saved_by_blender": bpy.app.version_string,
            "scene": {"fps": int(scene.render.fps), "fps_base": float(scene.render.fps_base),
                      "frame_start": int(scene.frame_start), "frame_end": int(scene.frame_end)}}
    if len(subjects) == 1:
        return {**head, **subjects[0], "materials": list(materials.values())}
    return {**head, "subjects": subjects, "materials": list(materials.values())}


def subjects_of(data):
    """[{"armature", "meshes"}] of a loaded source of either version."""
    return data["subjects"] if "subjects" in data else [{"armature": data["armature"], "meshes": data["meshes"]}]


def _dump_subject(bpy, scene, arm):
    bones = []
    for bone in arm.data.bones:  # parents come before their children
        _axis, roll = bpy.types.Bone.AxisRollFromMatrix(bone.matrix_local.to_3x3(),
                                                        axis=bone.tail_local - bone.head_local)
        bones.append({"name": bone.name, "head": _floats(bone.head_local), "tail": _floats(bone.tail_local),
                      "roll": float(roll), "parent": bone.parent.name if bone.parent else None,
                      "use_connect": bool(bone.use_connect), "use_deform": bool(bone.use_deform),
                      "matrix_local": _matrix(bone.matrix_local)})
    pose = {pb.name: {"rotation_mode": pb.rotation_mode, "lock_location": list(map(bool, pb.lock_location)),
                      "lock_rotation": list(map(bool, pb.lock_rotation)), "lock_scale": list(map(bool, pb.lock_scale)),
                      "constraints": [_dump_constraint(c) for c in pb.constraints]}
            for pb in arm.pose.bones}
    meshes = []
    for obj in scene.objects:
        if obj.type != "MESH" or not any(m.type == "ARMATURE" and m.object == arm for m in obj.modifiers):
            continue
        me = obj.data
        groups = [vg.name for vg in obj.vertex_groups]
        weights = [[] for _ in groups]
        for v in me.vertices:
            for g in v.groups:
                weights[g.group].append([v.index, float(g.weight)])
        meshes.append({
            "object": obj.name, "mesh": me.name, "transform": _transform(obj),
            "parent": obj.parent.name if obj.parent else None, "parent_type": obj.parent_type,
            "matrix_parent_inverse": _matrix(obj.matrix_parent_inverse),
            "vertices": [_floats(v.co) for v in me.vertices],
            "faces": [list(p.vertices) for p in me.polygons],
            "smooth": [bool(p.use_smooth) for p in me.polygons],
            "material_index": [int(p.material_index) for p in me.polygons],
            "materials": [m.name if m else None for m in me.materials],
            "vertex_groups": groups, "weights": weights,
            "modifiers": [{"name": m.name, "type": m.type, "object": m.object.name if m.object else None,
                           "use_vertex_groups": bool(m.use_vertex_groups),
                           "use_bone_envelopes": bool(m.use_bone_envelopes),
                           "use_deform_preserve_volume": bool(m.use_deform_preserve_volume)}
                          for m in obj.modifiers if m.type == "ARMATURE"],
        })
    if not meshes:
        raise ValueError(f"no mesh in scene {scene.name!r} is skinned to {arm.name!r}")
    return {"armature": {"object": arm.name, "data": arm.data.name, "transform": _transform(arm),
                         "display_type": arm.data.display_type, "bones": bones, "pose": pose},
            "meshes": meshes}


def _dump_constraint(c):
    out = {"type": c.type, "name": c.name}
    for key in ("owner_space", "use_limit_x", "use_limit_y", "use_limit_z", "min_x", "max_x", "min_y", "max_y",
                "min_z", "max_z", "use_transform_limit"):
        if hasattr(c, key):
            value = getattr(c, key)
            out[key] = float(value) if isinstance(value, float) else value
    return out


def save_source(data, path):
    with gzip.open(path, "wt", encoding="utf-8", compresslevel=9) as fh:
        json.dump(data, fh, separators=(",", ":"))


def load_source(path):
    with gzip.open(path, "rt", encoding="utf-8") as fh:
        data = json.load(fh)
    if data.get("format") != FORMAT or data.get("version") not in (VERSION, SEVERAL_VERSION):
        raise ValueError(f"{path} is not a portable subject (format {FORMAT} version {VERSION} or {SEVERAL_VERSION})")
    return data


def _apply_transform(obj, t):
    obj.rotation_mode = t["rotation_mode"]
    obj.location = t["location"]
    obj.rotation_euler = t["rotation_euler"]
    obj.rotation_quaternion = t["rotation_quaternion"]
    obj.scale = t["scale"]


def _build_material(bpy, m):
    mat = bpy.data.materials.new(m["name"])
    mat.diffuse_color = m["diffuse_color"]
    mat.roughness, mat.metallic = m["roughness"], m["metallic"]
    if not m["nodes"]:
        return mat
    if hasattr(mat, "use_nodes") and not mat.use_nodes:
        mat.use_nodes = True  # Blender < 5.0 makes no node tree otherwise; 5.x materials always have one
    tree = mat.node_tree
    tree.nodes.clear()
    nodes = {}
    for n in m["nodes"]:
        node = tree.nodes.new(n["type"])
        node.name = n["name"]
        node.location = n["location"]
        for key, value in n["settings"].items():
            if hasattr(node, key):
                try:
                    setattr(node, key, value)
                except (TypeError, ValueError, AttributeError):
                    pass  # a setting this Blender does not know: keep its default
        nodes[n["name"]] = node
    for n in m["nodes"]:  # after the settings: they can change which sockets exist
        node = nodes[n["name"]]
        for key, value in n["inputs"].items():
            index, identifier = key.split(":", 1)
            socket = _socket(node.inputs, identifier, int(index))
            if socket is not None and hasattr(socket, "default_value"):
                try:
                    socket.default_value = value
                except (TypeError, ValueError):
                    pass
    for link in m["links"]:
        out = _socket(nodes[link["from_node"]].outputs, link["from_socket"], link["from_index"])
        inp = _socket(nodes[link["to_node"]].inputs, link["to_socket"], link["to_index"])
        if out is not None and inp is not None:
            tree.links.new(out, inp)
    return mat


def _socket(sockets, identifier, index):
    """By identifier (stable across versions); by position among same-named ones when there are several."""
    same = [s for s in sockets if s.identifier == identifier]
    if len(same) == 1:
        return same[0]
    if 0 <= index < len(sockets) and sockets[index].identifier == identifier:
        return sockets[index]
    return same[0] if same else None


def build(data, scene=None):
    """Create the subjects described by `data` in the (empty) scene; returns the (first) armature object."""
    import bpy

    scene = scene or bpy.context.scene
    scene.render.fps, scene.render.fps_base = data["scene"]["fps"], data["scene"]["fps_base"]
    scene.frame_start, scene.frame_end = data["scene"]["frame_start"], data["scene"]["frame_end"]
    view_layer = scene.view_layers[0]
    materials, first = None, None
    for subject in subjects_of(data):
        arm = _build_armature(bpy, scene, view_layer, subject["armature"])
        if materials is None:  # after the first armature, as version 1 always built them
            materials = {m["name"]: _build_material(bpy, m) for m in data["materials"]}
        _build_meshes(bpy, scene, subject["meshes"], materials)
        first = first or arm
    view_layer.objects.active = None
    return first


def _build_armature(bpy, scene, view_layer, a):
    arm_data = bpy.data.armatures.new(a["data"])
    arm_data.display_type = a["display_type"]
    arm = bpy.data.objects.new(a["object"], arm_data)
    scene.collection.objects.link(arm)
    view_layer.objects.active = arm
    with bpy.context.temp_override(scene=scene, view_layer=view_layer, active_object=arm, object=arm,
                                   selected_objects=[arm], selected_editable_objects=[arm]):
        bpy.ops.object.mode_set(mode="EDIT")
        edit = {}
        for b in a["bones"]:
            eb = arm_data.edit_bones.new(b["name"])
            eb.head, eb.tail, eb.roll = b["head"], b["tail"], b["roll"]
            eb.use_deform = b["use_deform"]
            edit[b["name"]] = eb
        for b in a["bones"]:
            if b["parent"]:
                edit[b["name"]].parent = edit[b["parent"]]
                edit[b["name"]].use_connect = b["use_connect"]
        bpy.ops.object.mode_set(mode="OBJECT")
    _apply_transform(arm, a["transform"])
    for name, p in a["pose"].items():
        pb = arm.pose.bones[name]
        pb.rotation_mode = p["rotation_mode"]
        pb.lock_location, pb.lock_rotation, pb.lock_scale = p["lock_location"], p["lock_rotation"], p["lock_scale"]
        for c in p["constraints"]:
            con = pb.constraints.new(c["type"])
            con.name = c["name"]
            for key, value in c.items():
                if key not in ("type", "name") and hasattr(con, key):
                    setattr(con, key, value)
    return arm


def _build_meshes(bpy, scene, meshes, materials):
    from mathutils import Matrix

    for m in meshes:
        me = bpy.data.meshes.new(m["mesh"])
        me.from_pydata(m["vertices"], [], m["faces"])
        for name in m["materials"]:
            me.materials.append(materials.get(name))
        me.polygons.foreach_set("material_index", m["material_index"])
        me.polygons.foreach_set("use_smooth", m["smooth"])
        me.update()
        obj = bpy.data.objects.new(m["object"], me)
        scene.collection.objects.link(obj)
        for name, pairs in zip(m["vertex_groups"], m["weights"]):
            vg = obj.vertex_groups.new(name=name)
            for index, weight in pairs:
                vg.add([index], weight, "REPLACE")
        for mod in m["modifiers"]:
            new = obj.modifiers.new(mod["name"], "ARMATURE")
            new.object = bpy.data.objects.get(mod["object"]) if mod["object"] else None
            new.use_vertex_groups = mod["use_vertex_groups"]
            new.use_bone_envelopes = mod["use_bone_envelopes"]
            new.use_deform_preserve_volume = mod["use_deform_preserve_volume"]
        if m["parent"]:
            obj.parent = bpy.data.objects[m["parent"]]
            obj.parent_type = m["parent_type"]
        obj.matrix_parent_inverse = Matrix(m["matrix_parent_inverse"])
        _apply_transform(obj, m["transform"])


def main(argv):
    import bpy

    usage = ("usage: portable_subject.py dump SUBJECT.blend SOURCE.json.gz | "
             "blender -b --factory-startup --python portable_subject.py -- build SOURCE.json.gz SUBJECT.blend")
    if len(argv) != 3 or argv[0] not in ("dump", "build"):
        print(usage, file=sys.stderr)
        return 2
    mode, src, dst = argv
    if mode == "dump":
        bpy.ops.wm.open_mainfile(filepath=src)
        save_source(dump(), dst)
    else:
        data = load_source(src)
        bpy.ops.wm.read_homefile(use_empty=True)
        build(data)
        bpy.context.preferences.filepaths.save_version = 0  # no SUBJECT.blend1 beside it
        bpy.ops.wm.save_as_mainfile(filepath=dst, compress=True)
    print(f"portable_subject: {mode} {src} -> {dst} (Blender {bpy.app.version_string})")
    return 0


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    code = main(args)
    if code:
        sys.exit(code)
