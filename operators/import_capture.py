"""Import a capture folder: one Blender camera per calibrated camera, its video as the camera background.

`import_capture()` does the work and raises errors that name the problem and the fix; the operator
turns them into a report in the UI. The capture is fully validated (calibration, footage, sizes,
clips) before the scene is touched, so a failed import leaves the scene as it was.
"""
from pathlib import Path

import bpy
from bpy.props import BoolProperty, StringProperty

from ..addon.properties import CAMERA_COLLECTION
from ..core.errors import InputError
from .failures import user_message


class ClipLoadError(InputError):
    """Blender cannot open a camera's footage as a movie clip."""


def _clip_file(source: Path) -> Path:
    """The file Blender loads as the clip: the video itself, or the first image of an image folder."""
    if not source.is_dir():
        return source
    from ..core.capture.calibration import natural_key
    from ..core.capture.frames import IMAGE_EXTENSIONS

    images = sorted((p for p in source.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS),
                    key=lambda p: natural_key(p.name))
    if not images:
        raise ClipLoadError(f"{source} holds no images ({', '.join(IMAGE_EXTENSIONS)})")
    return images[0]


def _load_clips(capture):
    """{camera name: MovieClip}; on failure removes the clips it loaded and names the camera."""
    clips = {}
    for cam in capture.cameras:
        path = _clip_file(Path(capture.frames.source_path(cam.name)))
        try:
            clips[cam.name] = bpy.data.movieclips.load(str(path), check_existing=True)
        except RuntimeError as exc:
            for clip in clips.values():
                if clip.users == 0:
                    bpy.data.movieclips.remove(clip)
            raise ClipLoadError(f"camera '{cam.name}': Blender cannot open {path} as a movie clip ({exc}); "
                                f"convert it to an H.264 .mp4 or to a folder of numbered PNG images") from None
    return clips


def _camera_collection(scene):
    """The scene's 'Mocap Cameras' collection, emptied of the cameras of an earlier import."""
    coll = bpy.data.collections.get(CAMERA_COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(CAMERA_COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    for obj in list(coll.objects):
        data = obj.data
        bpy.data.objects.remove(obj)
        if isinstance(data, bpy.types.Camera) and data.users == 0:
            bpy.data.cameras.remove(data)
    return coll


def _attach_background(cam_obj, clip, scene_frame_start):
    data = cam_obj.data
    data.show_background_images = True
    bg = data.background_images.new()
    bg.source = "MOVIE_CLIP"
    bg.clip = clip
    bg.alpha = 1.0
    clip.frame_start = scene_frame_start  # capture frame 0 plays at the scene's first frame


def set_scene_fps(scene, fps: float):
    """Blender stores the rate as fps / fps_base: 29.97 becomes 30 / 1.001."""
    whole = max(1, int(round(fps)))
    scene.render.fps = whole
    scene.render.fps_base = whole / fps


def import_capture(context, folder, units="auto"):
    """Load `folder` and create its cameras in the scene; return the camera objects (calibration order)."""
    from ..addon.camera_bridge import activate_camera, create_blender_camera
    from ..core.capture.capture import load_capture

    folder = Path(bpy.path.abspath(str(folder)))  # "//videos" is relative to the .blend
    capture = load_capture(folder, units=None if units == "auto" else units)
    try:
        clips = _load_clips(capture)
        scene = context.scene
        coll = _camera_collection(scene)
        objects = [create_blender_camera(scene, cam, coll, set_render=False) for cam in capture.cameras]
        for cam, obj in zip(capture.cameras, objects):
            obj["mocap_distortion"] = [float(v) for v in cam.dist]  # kept for reference: Blender's view is undistorted
            _attach_background(obj, clips[cam.name], scene.frame_start)
        set_scene_fps(scene, capture.frames.fps)
        scene.frame_end = scene.frame_start + capture.frames.n_frames - 1
        activate_camera(scene, objects[0])
        props = scene.mocap
        props.capture_dir = str(folder)
        props.camera_count = len(objects)
        props.capture_frames = capture.frames.n_frames
        if not props.use_frame_range:
            props.frame_start, props.frame_end = 0, capture.frames.n_frames - 1
        return objects
    finally:
        capture.close()


class MOCAP_OT_import_capture(bpy.types.Operator):
    """Create one camera per calibrated camera of a capture folder, with its video as the background"""

    bl_idname = "mocap.import_capture"
    bl_label = "Import Capture"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(name="Capture Folder", subtype="DIR_PATH", options={"SKIP_SAVE"},
                              description="Capture folder (blank: the folder set in the Capture panel)")
    filter_folder: BoolProperty(default=True, options={"HIDDEN", "SKIP_SAVE"})

    def invoke(self, context, _event):
        if self.directory or context.scene.mocap.capture_dir:
            return self.execute(context)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        props = context.scene.mocap
        folder = self.directory or props.capture_dir
        if not folder:
            self.report({"ERROR"}, "No capture folder: set it in the Mocap > Capture panel, or pick one in the "
                                   "file browser")
            return {"CANCELLED"}
        try:
            objects = import_capture(context, folder, props.units)
        except Exception as exc:  # noqa: BLE001  (the capture's error names its fix; a bug says it is one)
            self.report({"ERROR"}, user_message(exc, "The import"))
            return {"CANCELLED"}
        fps = context.scene.render.fps / context.scene.render.fps_base
        self.report({"INFO"}, f"Imported {len(objects)} cameras, {props.capture_frames} frames at {fps:g} fps")
        return {"FINISHED"}


classes = (MOCAP_OT_import_capture,)
