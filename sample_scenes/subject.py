"""Build the sample subject in bpy: MakeHuman CC0 body, CMU-named rig, skin weights, clothes.

Called by generate.py; the only code (with generate.py) that reads the shared data folder.
"""
import json
from pathlib import Path

import numpy as np

# clothing regions by the bone that dominates a face
REGIONS = {
    "shirt": ["LowerBack", "Spine", "Spine1", "LeftShoulder", "RightShoulder", "LeftArm", "RightArm"],
    "trousers": ["Hips", "LHipJoint", "RHipJoint", "LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg"],
    "shoes": ["LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"],
    "skin": ["Neck", "Neck1", "Head", "LeftForeArm", "RightForeArm", "LeftHand", "RightHand",
             "LeftFingerBase", "RightFingerBase", "LeftHandFinger1", "RightHandFinger1", "LThumb", "RThumb"],
}
# linear-RGB base colours: blue-grey shirt, dark navy trousers, light skin, near-black shoes, dark hair
COLOURS = {
    "shirt": (0.08, 0.13, 0.22),
    "trousers": (0.022, 0.025, 0.035),
    "skin": (0.62, 0.40, 0.30),
    "shoes": (0.02, 0.018, 0.016),
    "hair": (0.03, 0.02, 0.012),
}
MATERIAL_ORDER = ["shirt", "trousers", "skin", "shoes", "hair"]


def read_obj_body(obj_path, group="body"):
    """Vertices (all, obj order) and the faces of one group, 0-based."""
    verts, faces, cur = [], [], None
    with open(obj_path) as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("g "):
                cur = line.split()[1] if len(line.split()) > 1 else None
            elif line.startswith("f ") and cur == group:
                faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:]])
    return np.array(verts), faces


def obj_group_vertices(obj_path):
    """{group name: vertex indices (0-based) of its faces} for every group of an obj (MakeHuman's joint cubes)."""
    groups, cur = {}, None
    with open(obj_path) as fh:
        for line in fh:
            if line.startswith("g "):
                cur = line.split()[1] if len(line.split()) > 1 else None
            elif line.startswith("f ") and cur:
                groups.setdefault(cur, set()).update(int(tok.split("/")[0]) - 1 for tok in line.split()[1:])
    return {k: sorted(v) for k, v in groups.items()}


def joint_from_mesh(spec, verts_blender, groups):
    """A bone end placed on the mesh by MakeHuman's rule: the centre of a joint cube (strategy CUBE) or the
    mean of listed vertices (MEAN), in Blender coordinates."""
    if spec["strategy"] == "CUBE":
        return verts_blender[groups[spec["cube_name"]]].mean(axis=0)
    if spec["strategy"] == "MEAN":
        return verts_blender[spec["vertex_indices"]].mean(axis=0)
    return np.array(spec["default_position"], dtype=float)


def obj_to_blender(v):
    """MakeHuman obj (Y-up, decimetres) -> Blender (Z-up, metres): (x, -z, y) * 0.1."""
    v = np.asarray(v, dtype=np.float64)
    return np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1) * 0.1


def load_subject_data(data_dir, rig_name="cmu_mb"):
    """The MakeHuman body with the rig `rig_name` (makehuman/rigs/rig.NAME.json and weights.NAME.json)."""
    data_dir = Path(data_dir) / "makehuman"
    verts, faces = read_obj_body(data_dir / "base.obj")
    used = sorted({i for f in faces for i in f})
    remap = {old: new for new, old in enumerate(used)}
    body_v = obj_to_blender(verts[used])
    body_f = [[remap[i] for i in f] for f in faces]
    rig = json.loads((data_dir / "rigs" / f"rig.{rig_name}.json").read_text())
    # The Mixamo file (MakeHuman 1.1's format) nests its bones, and its default positions are those of
    # MakeHuman's T-posed default character, not of base.obj: its joints are placed on this mesh instead
    on_mesh = isinstance(rig.get("bones"), dict)
    rig = rig["bones"] if on_mesh else rig
    weights = json.loads((data_dir / "rigs" / f"weights.{rig_name}.json").read_text())["weights"]
    W = np.zeros((len(used), len(rig)))
    bone_names = order_bones(rig)
    col = {b: k for k, b in enumerate(bone_names)}
    for bone, pairs in weights.items():
        for vi, w in pairs:
            if vi in remap:
                W[remap[vi], col[bone]] += w
    s = W.sum(axis=1, keepdims=True)
    if np.any(s <= 0):
        raise ValueError("some body vertices have no skin weight; the weights file does not match base.obj")
    W /= s
    floor = body_v[:, 2].min()
    body_v[:, 2] -= floor
    bones = {}
    if on_mesh:
        all_v, groups = obj_to_blender(verts), obj_group_vertices(data_dir / "base.obj")
    for name in bone_names:
        b = rig[name]
        if on_mesh:
            head, tail = (joint_from_mesh(b[end], all_v, groups) for end in ("head", "tail"))
        else:
            head = np.array(b["head"]["default_position"], dtype=float)
            tail = np.array(b["tail"]["default_position"], dtype=float)
        head[2] -= floor
        tail[2] -= floor
        bones[name] = dict(head=head, tail=tail, roll=float(b.get("roll", 0.0)), parent=b.get("parent") or None,
                           use_connect=bool(b.get("use_connect", False)))
    return dict(verts=body_v, faces=body_f, weights=W, bone_names=bone_names, bones=bones)


def order_bones(rig):
    """Bone names parents first (stable, alphabetical among siblings)."""
    out, seen = [], set()
    pending = sorted(rig)
    while pending:
        nxt = []
        for n in pending:
            p = rig[n].get("parent") or None
            if p is None or p in seen:
                out.append(n)
                seen.add(n)
            else:
                nxt.append(n)
        if len(nxt) == len(pending):
            raise ValueError(f"rig has bones whose parents are missing: {nxt}")
        pending = nxt
    return out


def face_regions(data):
    """Region name per face from the dominant bone (summed vertex weights), plus a hair cap."""
    W = data["weights"]
    names = data["bone_names"]
    V = data["verts"]
    region_of_bone = {b: r for r, bl in REGIONS.items() for b in bl}
    region_of_bone.update({f"mixamorig:{b}": r for b, r in list(region_of_bone.items())})  # the Mixamo rig's names
    head_name = next(n for n in names if n.split(":")[-1] == "Head")
    head = data["bones"][head_name]
    top = V[:, 2].max()
    out = []
    for f in data["faces"]:
        b = names[int(np.argmax(W[f].sum(axis=0)))]
        r = region_of_bone.get(b, "skin")
        if b == head_name:
            c = V[f].mean(axis=0)
            # cap: everything above the brow, and the back of the skull down to the nape
            if c[2] > top - 0.075 or (c[2] > head["head"][2] + 0.04 and c[1] > head["head"][1] + 0.035):
                r = "hair"
        out.append(r)
    return out


def make_material(bpy, name, rgb, roughness=0.7, noise=0.0):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    if noise > 0:
        # faint fabric mottling so the colour term sees cloth, not a flat paint
        tex = nt.nodes.new("ShaderNodeTexNoise")
        tex.inputs["Scale"].default_value = 60.0
        ramp = nt.nodes.new("ShaderNodeMixRGB")
        ramp.blend_type = "MULTIPLY"
        ramp.inputs["Fac"].default_value = noise
        ramp.inputs["Color1"].default_value = (*rgb, 1.0)
        nt.links.new(tex.outputs["Color"], ramp.inputs["Color2"])
        nt.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    mat.diffuse_color = (*rgb, 1.0)
    return mat


def build_subject(bpy, data, target_tris=5500, colours=None):
    """Armature 'Armature' + mesh 'Body' (decimated, weighted, clothed) in rest pose at the origin.
    colours: {region: linear RGB} overriding COLOURS (the busy scene's grey clothes, its second person)."""
    colours = {**COLOURS, **(colours or {})}
    scene = bpy.context.scene
    arm_data = bpy.data.armatures.new("Armature")
    arm = bpy.data.objects.new("Armature", arm_data)
    scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    arm.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    ebs = {}
    for name in data["bone_names"]:
        b = data["bones"][name]
        eb = arm_data.edit_bones.new(name)
        eb.head = b["head"].tolist()
        eb.tail = b["tail"].tolist()
        eb.roll = b["roll"]
        ebs[name] = eb
    for name in data["bone_names"]:
        b = data["bones"][name]
        if b["parent"]:
            ebs[name].parent = ebs[b["parent"]]
            ebs[name].use_connect = b["use_connect"]
    bpy.ops.object.mode_set(mode="OBJECT")

    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(data["verts"].tolist(), [], data["faces"])
    mesh.update()
    body = bpy.data.objects.new("Body", mesh)
    scene.collection.objects.link(body)
    mats = {}
    for r in MATERIAL_ORDER:
        mats[r] = make_material(bpy, f"mocap_{r}", colours[r], roughness=0.55 if r == "skin" else 0.8,
                                noise=0.25 if r in ("shirt", "trousers") else 0.0)
        mesh.materials.append(mats[r])
    regions = face_regions(data)
    mesh.polygons.foreach_set("material_index", [MATERIAL_ORDER.index(r) for r in regions])
    W = data["weights"]
    for k, name in enumerate(data["bone_names"]):
        vg = body.vertex_groups.new(name=name)
        idx = np.nonzero(W[:, k] > 1e-6)[0]
        for i in idx:
            vg.add([int(i)], float(W[i, k]), "REPLACE")

    # decimate (collapse) to the target triangle count, then re-normalise the weights
    n_tris = sum(len(p.vertices) - 2 for p in mesh.polygons)
    dec = body.modifiers.new("Decimate", "DECIMATE")
    dec.decimate_type = "COLLAPSE"
    dec.ratio = target_tris / n_tris
    dec.use_collapse_triangulate = True
    bpy.context.view_layer.objects.active = body
    with bpy.context.temp_override(object=body, active_object=body):
        bpy.ops.object.modifier_apply(modifier=dec.name)
    for v in body.data.vertices:
        total = sum(g.weight for g in v.groups)
        if total > 0:
            for g in v.groups:
                g.weight /= total
    for p in body.data.polygons:
        p.use_smooth = True
    mod = body.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    body.parent = arm
    return arm, body


# ---------------------------------------------------------------- an actor of other proportions (issue 15)
def _rig_arrays(data):
    from core.body.rig_presets import match_preset

    names = data["bone_names"]
    parents = np.array([names.index(data["bones"][n]["parent"]) if data["bones"][n]["parent"] else -1 for n in names])
    heads = np.array([data["bones"][n]["head"] for n in names], float)
    tails = np.array([data["bones"][n]["tail"] for n in names], float)
    return names, parents, heads, tails, match_preset(names)[1]


def scaled_subject_data(data, proportions):
    """The subject's data with `proportions` applied by the engine's own rule (core.actor.proportions.scale_rest):
    bones lengthened per segment, the skin moved with them, the soles kept on the floor."""
    from core.actor.proportions import bone_factors, scale_rest

    names, parents, heads, tails, roles = _rig_arrays(data)
    axes = (tails - heads) / np.linalg.norm(tails - heads, axis=1, keepdims=True)
    own, link = bone_factors(names, parents, roles, proportions)
    new_heads, verts = scale_rest(heads, axes, parents, np.arange(len(names)), own, link, data["verts"],
                                  data["weights"], proportions.overall, np.array([0.0, 0.0, 1.0]))
    out = dict(data, verts=verts, bones={})
    for k, n in enumerate(names):
        out["bones"][n] = dict(data["bones"][n], head=new_heads[k], tail=new_heads[k] + own[k] * (tails[k] - heads[k]))
    return out


def segment_lengths_of(data, rest, rest_names):
    """core.actor.proportions.segment_lengths of the body in `data` (rest orientations from `rest`, (B,4,4) of an
    armature with the same bone directions, bones named `rest_names`)."""
    from core.body.model import Skeleton, build_body
    from core.actor.proportions import segment_lengths

    names, parents, heads, _, _ = _rig_arrays(data)
    rest = np.array(rest, float)[[list(rest_names).index(n) for n in names]]
    rest[:, :3, 3] = heads
    faces = np.array([f[:3] for f in data["faces"]])
    body = build_body(Skeleton(list(names), parents, rest), data["verts"], faces, data["weights"])
    return segment_lengths(body)
