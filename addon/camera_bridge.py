"""Blender camera objects <-> core Camera. Thin: the formulas live in core/capture/camera.py.

Render resolution and pixel aspect are per *scene*, but each camera of a capture may have its own
image size. Every camera object created here therefore keeps its own size and pixel aspect as
custom properties (`mocap_resolution`, `mocap_pixel_aspect`); `activate_camera` makes a camera the
scene camera and copies those into scene.render, and `camera_from_object` prefers them over the
scene's settings. resolution_percentage is treated as a preview reduction and ignored: the camera
read back is always the full-resolution one.
"""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from ..core.capture.camera import BlenderCameraParams, Camera, CameraError, camera_from_blender, camera_to_blender

_RES_KEY = "mocap_resolution"
_ASPECT_KEY = "mocap_pixel_aspect"


def apply_camera(cam_obj, params: BlenderCameraParams, scene, set_render: bool = True) -> None:
    """Write `params` onto a Blender camera object (and, if set_render, onto the scene's render size)."""
    data = cam_obj.data
    data.type = "PERSP"
    data.lens_unit = "MILLIMETERS"
    data.sensor_fit = params.sensor_fit
    data.sensor_width = params.sensor_width
    data.sensor_height = params.sensor_height
    data.lens = params.lens
    data.shift_x = params.shift_x
    data.shift_y = params.shift_y
    cam_obj.matrix_world = Matrix(np.asarray(params.matrix_world, dtype=float).tolist())
    cam_obj[_RES_KEY] = [int(params.resolution_x), int(params.resolution_y)]
    cam_obj[_ASPECT_KEY] = [float(params.pixel_aspect_x), float(params.pixel_aspect_y)]
    if set_render:
        _set_render(scene, params.resolution_x, params.resolution_y, params.pixel_aspect_x, params.pixel_aspect_y)


def _set_render(scene, width, height, aspx, aspy) -> None:
    render = scene.render
    render.resolution_x = int(width)
    render.resolution_y = int(height)
    render.resolution_percentage = 100
    render.pixel_aspect_x = float(aspx)
    render.pixel_aspect_y = float(aspy)


def create_blender_camera(scene, cam: Camera, collection=None, sensor_width: float = 36.0,
                          sensor_fit: str = "AUTO", set_render: bool = True):
    """A new camera object named after `cam`, linked to `collection` (default: the scene's)."""
    params = camera_to_blender(cam, sensor_width=sensor_width, sensor_fit=sensor_fit)
    data = bpy.data.cameras.new(cam.name or "Camera")
    obj = bpy.data.objects.new(cam.name or "Camera", data)
    (collection or scene.collection).objects.link(obj)
    apply_camera(obj, params, scene, set_render=set_render)
    if set_render:
        scene.camera = obj
    return obj


def activate_camera(scene, cam_obj) -> None:
    """Make cam_obj the scene camera and give the scene its image size and pixel aspect."""
    scene.camera = cam_obj
    if _RES_KEY in cam_obj:
        w, h = cam_obj[_RES_KEY]
        aspx, aspy = cam_obj[_ASPECT_KEY] if _ASPECT_KEY in cam_obj else (1.0, 1.0)
        _set_render(scene, w, h, aspx, aspy)


def camera_from_object(cam_obj, scene, name: str | None = None) -> Camera:
    """Read a Blender camera back as an OpenCV camera (zero distortion)."""
    if cam_obj.type != "CAMERA":
        raise CameraError(f"object '{cam_obj.name}' is a {cam_obj.type}, not a camera; select a camera object")
    data = cam_obj.data
    if data.type != "PERSP":
        raise CameraError(f"camera '{cam_obj.name}' is {data.type}; only perspective cameras can be converted")
    render = scene.render
    if _RES_KEY in cam_obj:
        w, h = (int(v) for v in cam_obj[_RES_KEY])
        aspx, aspy = (float(v) for v in cam_obj[_ASPECT_KEY]) if _ASPECT_KEY in cam_obj else (1.0, 1.0)
    else:
        w, h = render.resolution_x, render.resolution_y
        aspx, aspy = render.pixel_aspect_x, render.pixel_aspect_y
    # data.lens is kept in sync with the field of view by Blender, whatever lens_unit shows.
    params = BlenderCameraParams(
        matrix_world=np.array(cam_obj.matrix_world, dtype=np.float64),
        lens=float(data.lens), sensor_width=float(data.sensor_width), sensor_height=float(data.sensor_height),
        sensor_fit=data.sensor_fit, shift_x=float(data.shift_x), shift_y=float(data.shift_y),
        resolution_x=int(w), resolution_y=int(h), pixel_aspect_x=float(aspx), pixel_aspect_y=float(aspy))
    return camera_from_blender(params, name=name or cam_obj.name)
