"""One module per user action; thin adapters between Blender properties and the engine."""

_OPERATOR_MODULES = ("import_capture", "setup_subject", "calibrate", "track", "track_batch", "export")
CLI_NAME = "markerless_mocap"
_cli_handle = None  # handle of `blender --command markerless_mocap`, None when not registered


def _classes():
    import importlib

    classes = []
    for name in _OPERATOR_MODULES:
        classes.extend(importlib.import_module(f"{__package__}.{name}").classes)
    return classes


def register():
    global _cli_handle
    import bpy

    for cls in _classes():
        bpy.utils.register_class(cls)
    if hasattr(bpy.utils, "register_cli_command"):  # Blender 4.2+
        from . import cli

        _cli_handle = bpy.utils.register_cli_command(CLI_NAME, cli.blender_command)


def unregister():
    global _cli_handle
    import bpy

    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
