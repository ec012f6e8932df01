"""Blender-facing state and UI. Imports bpy; computes nothing the engine computes."""

# Registration order matters: panels and preferences refer to the scene settings.
_MODULES = ("properties", "preferences", "panels")


def _modules():
    import importlib

    return [importlib.import_module(f"{__package__}.{name}") for name in _MODULES]


def register():
    for module in _modules():
        module.register()


def unregister():
    for module in reversed(_modules()):
        module.unregister()
