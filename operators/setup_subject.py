"""Check that the chosen armature can be tracked: DOF count, rig preset, and what stops it if not."""
import bpy

from .failures import user_message


def subject_armature(context):
    """The armature picked in the Subject panel, else the scene's only armature, which then fills the panel's
    field: the panel shows what is tracked, and a second armature added later (Apply to a Copy) changes nothing.
    SubjectError when there is none, or several and none picked."""
    from ..addon.scene_bridge import find_armature

    props = context.scene.mocap
    picked = props.armature
    if picked is not None:
        if picked.name not in context.scene.objects:
            from ..addon.scene_bridge import SubjectError

            raise SubjectError(f"armature {picked.name!r} is not in scene {context.scene.name!r}; "
                               f"pick one of this scene's armatures in the Subject panel")
        return picked
    props.armature = find_armature(context.scene)
    return props.armature


def ticked_actors(context):
    """With 'Track Every Armature' and several armatures in the scene: those ticked as actors (by name), else None."""
    from ..addon.scene_bridge import scene_armatures, ticked_armatures

    if not context.scene.mocap.every_armature or len(scene_armatures(context.scene)) < 2:
        return None
    return ticked_armatures(context.scene)


def several_actors(context):
    """The armatures ticked as actors when the Subject panel says to track several and more than one is, else []."""
    actors = ticked_actors(context) or []
    return actors if len(actors) > 1 else []


def subject_armatures(context):
    """The armatures Track solves: the several actors', the one ticked, else the one of `subject_armature`."""
    actors = ticked_actors(context)
    if actors is None:
        return [subject_armature(context)]
    if not actors:
        from ..addon.scene_bridge import SubjectError

        raise SubjectError("'Track Every Armature' is on but no armature is ticked as an actor: tick the actors to "
                           "track in the Subject panel")
    return actors


def check_subject(context):
    """Build the engine's body from the subject; return a summary dict (an InputError names a problem)."""
    from ..addon.scene_bridge import body_from_blender, find_skinned_mesh

    arm = subject_armature(context)
    mesh = find_skinned_mesh(arm, context.scene)
    body = body_from_blender(arm, mesh, context.scene)
    unweighted = int(body.unweighted.sum())
    problems = []
    if unweighted:
        problems.append(f"{unweighted} of {len(body.vertices)} vertices of {mesh.name!r} follow no deforming bone "
                        f"(they will not move): weight-paint them")
    return {"armature": arm.name, "mesh": mesh.name, "dofs": body.n_dof, "preset": body.preset or "custom",
            "bones": body.skeleton.n_bones, "vertices": len(body.vertices), "triangles": len(body.faces),
            "problems": problems}


class MOCAP_OT_check_subject(bpy.types.Operator):
    """Check that the armature and its skinned mesh can be tracked (bone mapping, weights, DOF)"""

    bl_idname = "mocap.check_subject"
    bl_label = "Check Rig"
    bl_options = {"REGISTER"}

    def execute(self, context):
        props = context.scene.mocap
        props.subject_checked = True
        try:
            info = check_subject(context)
        except Exception as exc:  # noqa: BLE001  (SubjectError, RigMappingError name the bones and the fix; else a bug)
            props.subject_dofs, props.subject_preset = 0, ""
            props.subject_problems = user_message(exc, "The rig check")
            self.report({"ERROR"}, props.subject_problems)
            return {"CANCELLED"}
        props.subject_dofs = info["dofs"]
        props.subject_preset = info["preset"]
        props.subject_problems = "; ".join(info["problems"])
        level = {"WARNING"} if info["problems"] else {"INFO"}
        self.report(level, f"{info['armature']}: {info['dofs']} DOF, preset {info['preset']}, "
                           f"mesh {info['mesh']} ({info['triangles']} triangles)"
                           + (f"; {props.subject_problems}" if info["problems"] else ""))
        return {"FINISHED"}


classes = (MOCAP_OT_check_subject,)
