"""Does a character of other proportions receive the actor's motion? Key a character with solved poses the
way `track` keys the user's character (core.actor.proportions.character_poses, scene_bridge.key_pose), export BVH
and FBX, import them back into an empty scene, and measure: the imported bone lengths against the
character's, and how far the character's feet are from the floor against the actor's.
The character: a copy of the subject with other proportions (addon/actor_bridge.py; --height, --factors), or
another rig in its own .blend (--character, e.g. sample_scenes/characters/mixamo.blend: other bone names,
bone count and bone placement), whose joint angles are matched to the actor's by DOF name.

    .venv/bin/python tools/character_check.py --scene S/subject.blend --result R
        [--height 1.2 | --factors JSON | --character C.blend] [--frames 0-29] [--out DIR]
    .venv/bin/python tools/character_check.py --result R --tracked   # the character `track` keyed in R

Prints one JSON object (also written to DIR/character_check.json).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _lowest_skin_z(bpy, bridge, mesh_obj, frames):
    out = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        out.append(float(bridge.evaluated_world_vertices(bpy.context, mesh_obj)[:, 2].min()))
    return np.array(out)


def _bone_lengths(arm, world=False):
    """Each bone's rest offset from its parent's head (what a BVH stores: its tails are not in the file), in
    armature space or (world=True, for FBX, which carries the object's transform and unit scale) in world space."""
    M = np.array(arm.matrix_world) if world else np.eye(4)
    head = lambda b: M[:3, :3] @ np.array(b.head_local) + M[:3, 3]
    return {b.name: float(np.linalg.norm(head(b) - head(b.parent))) for b in arm.data.bones if b.parent}


def _toe_heights(bpy, arm, frames, names=("LeftToeBase", "RightToeBase"), world=False):
    """Lowest toe-joint height per frame, armature space (BVH keeps no object transform) or world. Bones are
    matched without a namespace ("mixamorig:LeftToeBase")."""
    toes = [b.name for b in arm.pose.bones if b.name.split(":")[-1] in names]
    out = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        M = np.array(arm.matrix_world) if world else np.eye(4)
        out.append(min(float((M[:3, :3] @ np.array(arm.pose.bones[n].head) + M[:3, 3])[2]) for n in toes))
    return np.array(out)


def _max_difference(a, b):
    """Largest |a[n] - b[n]| over the bones both have, names matched without a namespace (FBX may drop it)."""
    strip = lambda d: {k.split(":")[-1]: v for k, v in d.items()}
    a, b = strip(a), strip(b)
    common = sorted(set(a) & set(b))
    if not common:
        raise ValueError(f"no bone names in common: {sorted(a)[:5]}... vs {sorted(b)[:5]}...")
    return float(max(abs(a[n] - b[n]) for n in common)), len(common)


def _append_character(bpy, bridge, scene, path):
    """Link the armature and mesh of `path` (a character .blend) into `scene`."""
    with bpy.data.libraries.load(str(path)) as (src, dst):
        dst.objects = list(src.objects)
    for obj in dst.objects:
        scene.collection.objects.link(obj)
    arm = next(o for o in dst.objects if o.type == "ARMATURE")
    return arm, bridge.find_skinned_mesh(arm, scene)


def check_character(bpy, package, subject_blend, poses, proportions, out_dir, actor_proportions=None,
                    character_blend=None):
    """poses (F,D): the actor's solved poses (on the subject, or on the subject scaled by actor_proportions).
    The character: the subject scaled by `proportions`, or (character_blend) the rig in that file."""
    bridge = __import__(f"{package}.addon.scene_bridge", fromlist=["x"])
    actor_bridge = __import__(f"{package}.addon.actor_bridge", fromlist=["x"])
    export = __import__(f"{package}.operators.export", fromlist=["x"])
    prop = __import__(f"{package}.core.actor.proportions", fromlist=["x"])

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.open_mainfile(filepath=str(subject_blend))
    scene = bpy.context.scene
    arm = bridge.find_armature(scene)
    subject = bridge.body_from_blender(arm, None, scene)
    actor = subject if actor_proportions is None else prop.scaled_body(subject, actor_proportions)
    if character_blend is not None:
        char_arm, char_mesh = _append_character(bpy, bridge, scene, character_blend)
    else:
        char_arm, char_mesh = actor_bridge.apply_proportions_to_copy(scene, arm, proportions, suffix="_character")
    # the character is tracked alone: hide the original so its keys and skin do not count
    bpy.data.objects.remove(bridge.find_skinned_mesh(arm, scene), do_unlink=True)
    bpy.data.objects.remove(arm, do_unlink=True)
    character = bridge.body_from_blender(char_arm, char_mesh, scene)
    # the DOF are named and ordered by joint role, so any preset's rig takes the actor's joint angles as they are
    if character.dof_names != actor.dof_names:
        raise ValueError(f"the character's DOF ({character.preset} rig) are not the actor's ({actor.preset} rig)")
    char_poses = prop.character_poses(actor, character, poses)
    frames = list(range(1, len(poses) + 1))
    for f, x in zip(frames, char_poses):
        bridge.key_pose(char_arm, character, x, f)
    char_low = _lowest_skin_z(bpy, bridge, char_mesh, frames)
    char_toes = _toe_heights(bpy, char_arm, frames)
    lengths = _bone_lengths(char_arm)
    subject_lengths = {n: float(np.linalg.norm(subject.skeleton.rest[i, :3, 3]
                                               - subject.skeleton.rest[subject.skeleton.parents[i], :3, 3]))
                       for i, n in enumerate(subject.skeleton.bone_names) if subject.skeleton.parents[i] >= 0}
    char_segments, actor_segments = prop.segment_lengths(character), prop.segment_lengths(actor)
    actor_low = actor.deform(np.asarray(poses))[..., 2].min(axis=1)
    floor_a, hip_a = prop.standing_heights(actor)
    floor_c, hip_c = prop.standing_heights(character)
    world_lengths = _bone_lengths(char_arm, world=True)
    world_toes = _toe_heights(bpy, char_arm, frames, world=True)
    bvh = export.export_bvh(bpy.context, char_arm, out_dir / "character.bvh", (frames[0], frames[-1]), scene=scene)
    fbx = export.export_fbx(bpy.context, char_arm, out_dir / "character.fbx", (frames[0], frames[-1]), scene=scene)

    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(fbx), anim_offset=0.0, automatic_bone_orientation=False)
    fbx_arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    fbx_back = _bone_lengths(fbx_arm, world=True)
    fbx_err, fbx_common = _max_difference(fbx_back, world_lengths)
    fbx_toes = _toe_heights(bpy, fbx_arm, frames, world=True)

    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(bvh), frame_start=frames[0], axis_forward="Y", axis_up="Z",
                            update_scene_duration=True)
    imported = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    back = _bone_lengths(imported)
    length_err, bvh_common = _max_difference(back, lengths)
    toes_back = _toe_heights(bpy, imported, frames)
    ratio = hip_c / hip_a
    report = {
        "frames": len(frames), "character_height_m": prop.segment_lengths(character)["height"],
        "actor_height_m": prop.segment_lengths(actor)["height"], "root_path_ratio": ratio,
        "character_bones": len(lengths) + 1, "character_preset": character.preset,
        "bvh_bones": len(back), "bvh_bones_matched": bvh_common, "bvh_bone_length_max_error_m": float(length_err),
        "character_vs_subject_bone_length_max_difference_m": (
            _max_difference(lengths, subject_lengths)[0] if set(lengths) & set(subject_lengths) else None),
        "segment_length_ratio_character_to_actor": {k: char_segments[k] / actor_segments[k] for k in (
            "height", "spine", "neck", "shoulder_width", "hip_width", "upper_arm", "forearm", "thigh", "shin",
            "foot")},
        "bvh_toe_height_vs_keyed_max_m": float(np.abs(toes_back - char_toes).max()),
        "fbx_bones": len(fbx_back), "fbx_bones_matched": fbx_common, "fbx_bone_length_max_error_m": float(fbx_err),
        "fbx_toe_height_vs_keyed_max_m": float(np.abs(fbx_toes - world_toes).max()),
        "character_lowest_skin_above_floor_m": {
            "median": float(np.median(char_low - floor_c)), "p5": float(np.percentile(char_low - floor_c, 5)),
            "p95": float(np.percentile(char_low - floor_c, 95)), "min": float((char_low - floor_c).min()),
            "max": float((char_low - floor_c).max())},
        "actor_lowest_skin_above_floor_m": {
            "median": float(np.median(actor_low - floor_a)), "min": float((actor_low - floor_a).min()),
            "max": float((actor_low - floor_a).max())},
        "character_minus_ratio_x_actor_lowest_m_max":
            float(np.abs((char_low - floor_c) - ratio * (actor_low - floor_a)).max()),
    }
    (out_dir / "character_check.json").write_text(json.dumps(report, indent=1))
    return report


def check_result(bpy, package, result_dir):
    """The files `track` wrote for the user's character (RESULT/tracked.blend, animation.bvh, animation.fbx):
    BVH and FBX re-imported with the keyed character's bone offsets, its toes where it was keyed, and its
    lowest skin point against the floor it stands on in the rest pose."""
    bridge = __import__(f"{package}.addon.scene_bridge", fromlist=["x"])
    prop = __import__(f"{package}.core.actor.proportions", fromlist=["x"])
    result_dir = Path(result_dir)
    with np.load(result_dir / "poses.npz") as z:
        n = len(z["poses"])
    bpy.ops.wm.open_mainfile(filepath=str(result_dir / "tracked.blend"))
    scene = bpy.context.scene
    arm = bridge.find_armature(scene)
    mesh = bridge.find_skinned_mesh(arm, scene)
    character = bridge.body_from_blender(arm, mesh, scene)
    frames = list(range(scene.frame_start, scene.frame_start + n))
    floor, _ = prop.standing_heights(character)
    low = _lowest_skin_z(bpy, bridge, mesh, frames) - floor
    lengths, world_lengths = _bone_lengths(arm), _bone_lengths(arm, world=True)
    toes, world_toes = _toe_heights(bpy, arm, frames), _toe_heights(bpy, arm, frames, world=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(result_dir / "animation.fbx"), anim_offset=0.0,
                             automatic_bone_orientation=False)
    fbx_arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    fbx_err, fbx_common = _max_difference(_bone_lengths(fbx_arm, world=True), world_lengths)
    fbx_toes = _toe_heights(bpy, fbx_arm, frames, world=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(result_dir / "animation.bvh"), frame_start=frames[0], axis_forward="Y",
                            axis_up="Z", update_scene_duration=True)
    bvh_arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    bvh_err, bvh_common = _max_difference(_bone_lengths(bvh_arm), lengths)
    bvh_toes = _toe_heights(bpy, bvh_arm, frames)
    report = {"frames": n, "character_preset": character.preset, "character_bones": len(lengths) + 1,
              "character_height_m": prop.segment_lengths(character)["height"],
              "bvh_bones_matched": bvh_common, "bvh_bone_length_max_error_m": bvh_err,
              "bvh_toe_height_vs_keyed_max_m": float(np.abs(bvh_toes - toes).max()),
              "fbx_bones_matched": fbx_common, "fbx_bone_length_max_error_m": fbx_err,
              "fbx_toe_height_vs_keyed_max_m": float(np.abs(fbx_toes - world_toes).max()),
              "character_lowest_skin_above_floor_m": {
                  "median": float(np.median(low)), "p5": float(np.percentile(low, 5)),
                  "p95": float(np.percentile(low, 95)), "min": float(low.min()), "max": float(low.max())}}
    (result_dir / "character_check.json").write_text(json.dumps(report, indent=1))
    return report


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", type=Path)
    ap.add_argument("--result", type=Path, required=True, help="result folder (poses.npz; actor.json if calibrated)")
    ap.add_argument("--tracked", action="store_true",
                    help="check the character track keyed and exported in RESULT (tracked.blend, animation.bvh/.fbx)")
    ap.add_argument("--height", type=float, help="the character: the subject scaled to this height (m)")
    ap.add_argument("--factors", help="the character: segment factors as JSON, e.g. '{\"thigh\": 1.1}'")
    ap.add_argument("--character", type=Path, help="the character: the rig in this .blend (armature + skinned mesh)")
    ap.add_argument("--frames", help="poses A-B of the result (default: all)")
    ap.add_argument("--out", type=Path, help="where character.bvh and character_check.json go (default: RESULT)")
    args = ap.parse_args(argv)
    import bpy

    if args.tracked:
        print(json.dumps(check_result(bpy, "markerless_mocap", args.result), indent=1))
        return 0
    if args.scene is None:
        ap.error("--scene is needed (except with --tracked)")
    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.actor.actor_file import load_actor, proportions_for_body
    from markerless_mocap.core.actor.proportions import Proportions, segment_lengths

    with np.load(args.result / "poses.npz") as z:
        poses = z["poses"]
    if args.frames:
        a, _, b = args.frames.partition("-")
        poses = poses[int(a):int(b) + 1]
    bpy.ops.wm.open_mainfile(filepath=str(args.scene))
    subject = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
    actor_props = None
    if (args.result / "actor.json").is_file():
        actor_props = proportions_for_body(load_actor(args.result / "actor.json"), subject)
    if args.height:
        proportions = Proportions.uniform(args.height / segment_lengths(subject)["height"])
    else:
        factors = json.loads(args.factors or "{}")
        proportions = Proportions(factors, factors.pop("overall", 1.0))
    report = check_character(bpy, "markerless_mocap", args.scene, poses, proportions, args.out or args.result,
                             actor_proportions=actor_props, character_blend=args.character)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
