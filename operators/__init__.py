"""One module per user action; thin adapters between Blender properties and the engine."""


def register():
    pass


def unregister():
    pass
