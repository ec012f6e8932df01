# SPDX-License-Identifier: GPL-3.0-or-later
"""Markerless Mocap: fit your own rigged character to calibrated multi-camera video.

register()/unregister() wire the Blender side (addon/, operators/). Nothing here imports
bpy at module level, so the bpy-free engine in core/ stays importable on its own.
"""


def register():
    from . import addon, operators

    addon.register()
    operators.register()


def unregister():
    from . import addon, operators

    operators.unregister()
    addon.unregister()
