"""Blender-facing state and UI. Imports bpy; computes nothing the engine computes."""


def register():
    pass


def unregister():
    pass
