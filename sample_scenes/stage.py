"""The room around the subject: textured floor and walls, furniture-like boxes, lights, and for
the uncontrolled scene changing light and moving things. Everything stays outside a 2.6 m disc
around the action centre so nothing stands between a camera and the person."""
import math

import numpy as np


def _mat(bpy, name, build):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    colour = build(nt)
    if colour is not None:
        nt.links.new(colour, bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = 0.75
    return mat


def _two_tone(nt, tex, c1, c2):
    mix = nt.nodes.new("ShaderNodeMixRGB")
    mix.inputs["Color1"].default_value = (*c1, 1)
    mix.inputs["Color2"].default_value = (*c2, 1)
    out = tex.outputs.get("Fac") or tex.outputs[0]
    nt.links.new(out, mix.inputs["Fac"])
    return mix.outputs["Color"]


def planks(bpy, name, c1, c2, scale=1.0):
    def build(nt):
        coord = nt.nodes.new("ShaderNodeTexCoord")
        brick = nt.nodes.new("ShaderNodeTexBrick")
        brick.inputs["Scale"].default_value = 0.6 * scale
        brick.inputs["Color1"].default_value = (*c1, 1)
        brick.inputs["Color2"].default_value = (*c2, 1)
        brick.inputs["Mortar"].default_value = (c2[0] * 0.4, c2[1] * 0.4, c2[2] * 0.4, 1)
        brick.inputs["Mortar Size"].default_value = 0.008
        brick.inputs["Brick Width"].default_value = 1.6
        brick.inputs["Row Height"].default_value = 0.18
        nt.links.new(coord.outputs["Object"], brick.inputs["Vector"])
        grain = nt.nodes.new("ShaderNodeTexWave")
        grain.inputs["Scale"].default_value = 3.0 * scale
        grain.inputs["Distortion"].default_value = 6.0
        nt.links.new(coord.outputs["Object"], grain.inputs["Vector"])
        mul = nt.nodes.new("ShaderNodeMixRGB")
        mul.blend_type = "MULTIPLY"
        mul.inputs["Fac"].default_value = 0.35
        nt.links.new(brick.outputs["Color"], mul.inputs["Color1"])
        nt.links.new(grain.outputs["Color"], mul.inputs["Color2"])
        return mul.outputs["Color"]
    return _mat(bpy, name, build)


def noisy(bpy, name, c1, c2, scale=4.0, kind="noise"):
    def build(nt):
        coord = nt.nodes.new("ShaderNodeTexCoord")
        if kind == "noise":
            tex = nt.nodes.new("ShaderNodeTexNoise")
            tex.inputs["Detail"].default_value = 8.0
        elif kind == "voronoi":
            tex = nt.nodes.new("ShaderNodeTexVoronoi")
        elif kind == "wave":
            tex = nt.nodes.new("ShaderNodeTexWave")
            tex.inputs["Distortion"].default_value = 4.0
        elif kind == "checker":
            tex = nt.nodes.new("ShaderNodeTexChecker")
        elif kind == "magic":
            tex = nt.nodes.new("ShaderNodeTexMagic")
        tex.inputs["Scale"].default_value = scale
        nt.links.new(coord.outputs["Object"], tex.inputs["Vector"])
        return _two_tone(nt, tex, c1, c2)
    return _mat(bpy, name, build)


def box(bpy, name, centre, size, mat, rot_z=0.0):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=centre, rotation=(0, 0, rot_z))
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = size
    ob.data.materials.append(mat)
    return ob


def build_room(bpy, rng, uncontrolled, grey=False):
    """Floor, four walls, furniture, posters. Returns the objects that move (may be empty).
    grey: the busy scene's room - grey walls and a grey floor, close to the subject's grey clothes."""
    if grey:
        floor_mat = planks(bpy, "floor_planks", (0.075, 0.075, 0.07), (0.05, 0.05, 0.048))
    else:
        floor_mat = planks(bpy, "floor_planks", (0.32, 0.19, 0.09), (0.22, 0.12, 0.05))
    bpy.ops.mesh.primitive_plane_add(size=14.0, location=(0, 0, 0))
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(floor_mat)
    # a rug; in the uncontrolled scene a dark one under part of the path (low contrast with the trousers)
    rug_cols = ((0.03, 0.035, 0.05), (0.06, 0.05, 0.06)) if uncontrolled else ((0.35, 0.08, 0.06), (0.5, 0.42, 0.25))
    rug = noisy(bpy, "rug", *rug_cols, scale=9.0, kind="checker" if not uncontrolled else "noise")
    bpy.ops.mesh.primitive_plane_add(size=1.0,
                                     location=(0.9 if uncontrolled else -1.9, 0.4 if uncontrolled else 1.5, 0.004))
    r = bpy.context.active_object
    r.name = "Rug"
    r.scale = (2.2, 3.0, 1.0)
    r.data.materials.append(rug)

    wall_cols = [((0.55, 0.5, 0.42), (0.45, 0.42, 0.36)), ((0.35, 0.45, 0.38), (0.28, 0.36, 0.3)),
                 ((0.6, 0.56, 0.5), (0.5, 0.47, 0.42)), ((0.42, 0.36, 0.3), (0.34, 0.29, 0.24))]
    if grey:
        # every wall a mottled grey around the shirt's grey (and one darker, near the trousers)
        wall_cols = [((0.17, 0.17, 0.16), (0.12, 0.12, 0.115)), ((0.15, 0.155, 0.16), (0.11, 0.11, 0.115)),
                     ((0.19, 0.185, 0.17), (0.13, 0.13, 0.12)), ((0.06, 0.06, 0.06), (0.04, 0.04, 0.042))]
    elif uncontrolled:
        # one wall the colour of the shirt: the silhouette is hard to cut out against it
        wall_cols[1] = ((0.09, 0.14, 0.22), (0.07, 0.11, 0.18))
    half = 5.5
    for k, (cx, cy, rz) in enumerate([(0, half, 0), (half, 0, math.pi / 2), (0, -half, 0), (-half, 0, math.pi / 2)]):
        m = noisy(bpy, f"wall_{k}", *wall_cols[k], scale=2.5 + k, kind="noise")
        box(bpy, f"Wall{k}", (cx, cy, 1.5), (11.0, 0.1, 3.0), m, rz)
        # skirting board and a poster per wall
        sk = noisy(bpy, f"skirt_{k}", (0.9, 0.9, 0.88), (0.8, 0.8, 0.78), 1.0)
        box(bpy, f"Skirting{k}", (cx * 0.99, cy * 0.99, 0.06), (11.0, 0.04, 0.12), sk, rz)
        kinds = ["magic", "checker", "voronoi", "wave"]
        for q, off in enumerate((-3.2, -0.6, 2.4)):
            pc = rng.uniform(0.05, 0.8, size=(2, 3))
            pm = noisy(bpy, f"poster_{k}_{q}", tuple(pc[0]), tuple(pc[1]), scale=float(rng.uniform(3, 9)),
                       kind=kinds[(k + q) % 4])
            off += float(rng.uniform(-0.5, 0.5))
            pos = (cx * 0.985 + (off if rz == 0 else 0), cy * 0.985 + (off if rz != 0 else 0),
                   float(rng.uniform(1.2, 2.0)))
            box(bpy, f"Poster{k}_{q}", pos, (float(rng.uniform(0.5, 1.3)), 0.02, float(rng.uniform(0.4, 1.0))), pm, rz)

    # furniture-like boxes along the walls (radius > 4.2 m from the centre)
    wood = noisy(bpy, "wood", (0.4, 0.25, 0.12), (0.25, 0.14, 0.06), 6.0, "wave")
    metal = noisy(bpy, "metal", (0.5, 0.52, 0.55), (0.35, 0.36, 0.4), 20.0, "noise")
    fabric = noisy(bpy, "fabric", (0.5, 0.12, 0.1), (0.3, 0.06, 0.05), 12.0, "voronoi")
    boxes_mat = noisy(bpy, "cardboard", (0.55, 0.42, 0.25), (0.45, 0.33, 0.18), 15.0, "noise")
    furniture = [
        ("Shelf", (4.9, 2.5, 1.0), (0.5, 1.6, 2.0), wood, 0.0),
        ("Cabinet", (-4.9, -2.0, 0.55), (0.6, 1.2, 1.1), metal, 0.0),
        ("Sofa", (-2.5, 4.8, 0.4), (2.2, 0.9, 0.8), fabric, 0.0),
        ("Table", (2.8, -4.6, 0.38), (1.6, 0.9, 0.76), wood, 0.1),
        ("Boxes", (-4.6, 3.9, 0.3), (0.6, 0.6, 0.6), boxes_mat, 0.4),
        ("Boxes2", (-4.5, 3.1, 0.25), (0.5, 0.5, 0.5), boxes_mat, -0.2),
        ("Locker", (4.8, -2.8, 0.95), (0.5, 0.9, 1.9), metal, 0.0),
        ("Bench", (0.5, 4.9, 0.25), (1.8, 0.45, 0.5), wood, 0.0),
        ("Crate", (-3.6, -4.6, 0.35), (0.7, 0.7, 0.7), wood, 0.3),
        ("Desk", (4.7, 0.3, 0.37), (0.8, 1.4, 0.74), wood, 0.0),
        ("Monitor", (4.8, 0.3, 0.99), (0.08, 0.6, 0.4), metal, 0.0),
        ("Shelf2", (-4.9, 0.9, 0.9), (0.4, 1.2, 1.8), wood, 0.0),
        ("Books", (-4.85, 0.9, 1.2), (0.3, 1.0, 0.25), fabric, 0.0),
        ("Stool", (1.6, -4.7, 0.22), (0.4, 0.4, 0.44), metal, 0.6),
        ("Bin", (-1.2, 4.9, 0.2), (0.35, 0.35, 0.4), boxes_mat, 0.0),
    ]
    for name, c, s, m, rz in furniture:
        box(bpy, name, c, s, m, rz)
    # a floor lamp and a plant-ish column (round shapes among the boxes)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.2, depth=1.0, location=(3.9, 4.3, 0.5))
    pot = bpy.context.active_object
    pot.data.materials.append(noisy(bpy, "pot", (0.6, 0.3, 0.15), (0.5, 0.24, 0.1), 5.0))
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.55, subdivisions=2, location=(3.9, 4.3, 1.4))
    leaves = bpy.context.active_object
    leaves.data.materials.append(noisy(bpy, "leaves", (0.08, 0.25, 0.05), (0.03, 0.12, 0.02), 14.0, "voronoi"))

    moving = []
    if uncontrolled:
        # a box pushed along the far wall, and a lamp swinging from the ceiling
        cart = box(bpy, "SlidingBox", (-3.0, 4.6, 0.35), (0.7, 0.5, 0.7), fabric)
        moving.append(cart)
        bpy.ops.object.empty_add(location=(-1.5, -4.2, 3.0))
        pivot = bpy.context.active_object
        pivot.name = "LampPivot"
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.18, location=(-1.5, -4.2, 1.9))
        bulb = bpy.context.active_object
        bulb.name = "SwingingLamp"
        em = bpy.data.materials.new("lamp_glow")
        em.use_nodes = True
        b = em.node_tree.nodes.get("Principled BSDF")
        b.inputs["Base Color"].default_value = (1.0, 0.85, 0.6, 1)
        b.inputs["Emission Color"].default_value = (1.0, 0.8, 0.5, 1)
        b.inputs["Emission Strength"].default_value = 6.0
        bulb.data.materials.append(em)
        bulb.parent = pivot
        bulb.location = (0, 0, -1.1)
        bpy.ops.mesh.primitive_cylinder_add(radius=0.01, depth=1.1, location=(0, 0, 0))
        cord = bpy.context.active_object
        cord.parent = pivot
        cord.location = (0, 0, -0.55)
        moving += [pivot]
    return moving


def build_lights(bpy, uncontrolled, n_frames, busy=False):
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.35, 0.38, 0.42, 1)
    bg.inputs["Strength"].default_value = 0.25

    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy = 2.2
    sun_data.angle = math.radians(12)
    sun = bpy.data.objects.new("Sun", sun_data)
    scene.collection.objects.link(sun)
    sun.rotation_euler = (math.radians(40), math.radians(15), math.radians(30))
    areas = []
    for k, (x, y) in enumerate([(-1.5, -1.0), (1.8, 1.2)]):
        ad = bpy.data.lights.new(f"Ceiling{k}", "AREA")
        ad.energy = 450.0
        ad.size = 1.5
        ob = bpy.data.objects.new(f"Ceiling{k}", ad)
        ob.location = (x, y, 2.95)
        scene.collection.objects.link(ob)
        areas.append(ad)
    if busy:
        _busy_lights(bpy, sun, sun_data, areas, bg, n_frames)
    elif uncontrolled:
        # illumination drifts over the clip (clouds / a dimmer): strength and colour keyed
        keys = np.linspace(1, n_frames, 5)
        # all sources follow one envelope (a cloud passing, a dimmer): the mean image brightness
        # swings by about a third, and the colour goes from warm to cool and back
        envelope = [1.0, 0.3, 1.15, 0.4, 0.8]
        tints = [(1.0, 0.85, 0.65), (0.7, 0.8, 1.0), (1.0, 0.82, 0.6), (0.72, 0.82, 1.0), (1.0, 0.95, 0.85)]
        # the hanging lamp is on the same dimmer, so the whole image changes together, as it does with a
        # camera's exposure and white-balance swings (its swinging still moves light and shadows locally)
        pl = _swinging_lamp_light(bpy)
        for f, e, c in zip(keys, envelope, tints):
            _key_light_level(sun_data, areas, bg, pl, f, e, c, (3.0, 450.0, 150.0))


def _swinging_lamp_light(bpy):
    """The point light that hangs from the swinging lamp (its pivot is built with the room)."""
    pl = bpy.data.lights.new("LampLight", "POINT")
    pl.color = (1.0, 0.8, 0.5)
    lamp = bpy.data.objects.new("LampLight", pl)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.parent = bpy.data.objects["LampPivot"]
    lamp.location = (0, 0, -1.35)
    return pl


def _key_light_level(sun_data, areas, bg, pl, frame, level, colour, energies, tint_world=False):
    """Key every source at one dimmer level and colour; energies = (sun, each area, lamp) at level 1."""
    f = float(frame)
    sun_data.energy = energies[0] * level
    sun_data.color = colour
    sun_data.keyframe_insert("energy", frame=f)
    sun_data.keyframe_insert("color", frame=f)
    bg.inputs["Strength"].default_value = 0.3 * level
    bg.inputs["Strength"].keyframe_insert("default_value", frame=f)
    if tint_world:
        bg.inputs["Color"].default_value = (*colour, 1)
        bg.inputs["Color"].keyframe_insert("default_value", frame=f)
    for ad in areas:
        ad.energy = energies[1] * level
        ad.color = colour
        ad.keyframe_insert("energy", frame=f)
        ad.keyframe_insert("color", frame=f)
    pl.energy = energies[2] * level
    pl.keyframe_insert("energy", frame=f)


def _busy_lights(bpy, sun, sun_data, areas, bg, n_frames):
    """The busy scene: every source on one fast dimmer (about 8x between the darkest and the brightest
    key) that swings between warm tungsten and cool daylight, a low sun that sweeps round the room
    (its shadows move across the floor and the walls), and the swinging lamp on the same dimmer."""
    keys = np.linspace(1, n_frames, 8)
    envelope = [1.0, 0.16, 0.85, 0.13, 1.1, 0.3, 0.95, 0.2]
    warm, cool = (1.0, 0.68, 0.42), (0.6, 0.76, 1.0)
    tints = [warm, cool, cool, warm, cool, warm, warm, cool]
    sun_data.angle = math.radians(3)
    pl = _swinging_lamp_light(bpy)
    for f, e, c in zip(keys, envelope, tints):
        _key_light_level(sun_data, areas, bg, pl, f, e, c, (4.0, 400.0, 200.0), tint_world=True)
    # the sun sweeps 150 degrees round the room at a low elevation: long shadows that move
    for f in np.linspace(1, n_frames, 6):
        a = (f - 1) / max(n_frames - 1, 1)
        sun.rotation_euler = (math.radians(58 - 10 * math.sin(math.pi * a)), 0.0, math.radians(-60 + 150 * a))
        sun.keyframe_insert("rotation_euler", frame=float(f))


def animate_moving(bpy, moving, n_frames):
    for ob in moving:
        if ob.name == "SlidingBox":
            ob.location = (-3.2, 4.6, 0.35)
            ob.keyframe_insert("location", frame=1)
            ob.location = (2.6, 4.6, 0.35)
            ob.keyframe_insert("location", frame=n_frames)
        elif ob.name == "LampPivot":
            period = 48.0
            for f in range(1, n_frames + 1, 4):
                ob.rotation_euler = (math.radians(28) * math.sin(2 * math.pi * f / period), 0, 0)
                ob.keyframe_insert("rotation_euler", frame=f)
