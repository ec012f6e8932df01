"""F-curves of an object's action across Blender versions (the one place that knows the difference).

Blender 4.4 introduced layered actions (slots + channelbags) and 5.0 removed `Action.fcurves`;
4.2-4.3 only have `Action.fcurves`. Everything else in the add-on asks this module.
"""


def object_fcurves(obj):
    """The F-curves animating `obj` through its active action (empty list when it has none)."""
    anim = obj.animation_data
    action = anim.action if anim else None
    if action is None:
        return []
    try:
        from bpy_extras.anim_utils import action_get_channelbag_for_slot
    except ImportError:  # Blender < 4.4: one flat list per action
        return list(action.fcurves)
    slot = getattr(anim, "action_slot", None)
    if slot is None:
        return list(getattr(action, "fcurves", []))
    channelbag = action_get_channelbag_for_slot(action, slot)
    return list(channelbag.fcurves) if channelbag is not None else []


def keyed_frames(obj, data_path_prefix=""):
    """Sorted frame numbers (floats) that hold a key on any F-curve whose data path starts with the prefix."""
    frames = set()
    for fc in object_fcurves(obj):
        if fc.data_path.startswith(data_path_prefix):
            frames.update(kp.co[0] for kp in fc.keyframe_points)
    return sorted(frames)


def keyed_frame_range(obj):
    """(first, last) keyed frame as ints, or None when `obj` has no keys."""
    frames = keyed_frames(obj)
    if not frames:
        return None
    return int(round(frames[0])), int(round(frames[-1]))
