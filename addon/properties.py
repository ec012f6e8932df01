"""Scene settings of the add-on (`scene.mocap`): capture, subject, tracker settings, run state, results.

Plain data only. The operators read these, call the engine, and write the outcome back here so
the panels can show it. The tracker's choices and their defaults come from core/tracking/options.py, and
`tracking_settings()` translates them into the engine's settings as the command line does.
"""
import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..core.batch.plan import DEFAULT_CHUNK_FRAMES
from ..core.tracking.fast_arms import FAST_ARM_FROM
from ..core.tracking.foot_contact import CONTACT_SPEED
from ..core.tracking.options import OPTIONS, settings_from_choices
from ..core.tracking.smoothing import DEFAULT_CUTOFF_HZ

# The Track panel's choices, from core/tracking/options.py (the command line's come from there too)
ALGORITHMS = OPTIONS["algorithm"].enum_items()
LIKELIHOODS = OPTIONS["likelihood"].enum_items()
PRESETS = OPTIONS["preset"].enum_items()
BACKENDS = OPTIONS["backend"].enum_items()


def _apply_preset(props, context):
    """Show the preset's search budget in the Particles / Iterations fields (they stay editable)."""
    from ..core.tracking.settings import TrackingSettings

    settings = TrackingSettings.preset(props.preset)
    props.particles, props.iterations = settings.particles, settings.iterations


def _enum(name, **kwargs):
    option = OPTIONS[name]
    return EnumProperty(name=option.label, items=option.enum_items(), default=option.default,
                        description=option.description, **kwargs)


def _number(name, prop, **kwargs):
    option = OPTIONS[name]
    return prop(name=option.label, default=option.default, description=option.description, **kwargs)


UNITS = (
    ("auto", "Auto", "Use the unit written in the calibration file (metres when it says nothing)"),
    ("m", "Metres", "The calibration's translations are in metres"),
    ("cm", "Centimetres", "The calibration's translations are in centimetres"),
    ("mm", "Millimetres", "The calibration's translations are in millimetres"),
)

CAMERA_COLLECTION = "Mocap Cameras"

# Where Track runs: here, frame by frame, or cut into chunks by the batch runner (operators/track_batch.py)
RUN_ON = (
    ("this", "This Blender", "Track here, keying each frame as it is solved"),
    ("local", "Local Processes", "Cut the take into chunks tracked by several processes on this computer at once; "
                                "the stitched take is keyed when it is done"),
    ("cluster", "Scheduler", "Cut the take into chunks tracked on a Dask cluster (workers on other computers read the "
                             "capture and write the results on shared storage); keyed when it is done"),
)
BATCH_SCOPE = (
    ("take", "This Take", "The capture of the Capture panel"),
    ("folder", "Folder of Captures", "Every capture in a folder, each a take tracked with this armature; the last "
                                     "one is keyed here, every one has its result folder"),
)


# Where each segment a user can measure starts and ends on the actor (the rig's joints, core/actor/proportions.py)
MEASURED_SEGMENTS = (
    ("spine", "Spine", "from the pelvis, between the hip joints, to the base of the neck"),
    ("neck", "Neck", "from the base of the neck to the base of the skull"),
    ("shoulder_width", "Shoulder Width", "between the centres of the two shoulder joints"),
    ("hip_width", "Hip Width", "between the centres of the two hip joints"),
    ("upper_arm", "Upper Arm", "shoulder joint to elbow"),
    ("forearm", "Forearm", "elbow to wrist"),
    ("thigh", "Thigh", "hip joint to knee"),
    ("shin", "Shin", "knee to ankle"),
    ("foot", "Foot", "ankle to the base of the toes"),
)


def _measured_length(segment):
    """A length measured on the actor, 0 while unmeasured (the calibration's from the footage)."""
    label, where = next((label, where) for key, label, where in MEASURED_SEGMENTS if key == segment)
    # no tight max: a typo (24.5 for 0.245) must reach the range check and be named, not clamped to look valid
    return FloatProperty(name=f"Measured {label}", default=0.0, min=0.0, max=1000.0, soft_max=1.2, precision=3,
                         subtype="DISTANCE", unit="LENGTH",
                         description=f"The actor's {label.lower()} ({where}) if you have measured it: the "
                                     "calibrated body gets exactly this length (0: as the footage gives it)")


def measured_length_fields():
    """{field: property} of the lengths a user can measure on an actor: the height and MEASURED_SEGMENTS."""
    height = FloatProperty(name="Measured Height", default=0.0, min=0.0, max=3.0, precision=3,
                           subtype="DISTANCE", unit="LENGTH",
                           description="The actor's height if you have measured it: the calibrated body is "
                                       "scaled to it (0: as the footage gives it)")
    # the footage reads some lengths only within 5-10 % (docs/actor-calibration.md); a tape measure's win
    return {"actor_height": height, **{f"actor_{key}": _measured_length(key) for key, _l, _w in MEASURED_SEGMENTS}}


def with_measured_lengths(cls):
    """The class with measured_length_fields as properties (the Subject panel's for one actor, each armature's
    for several)."""
    cls.__annotations__.update(measured_length_fields())
    return cls


@with_measured_lengths
class MocapMeasuredLengths(bpy.types.PropertyGroup):
    """One actor's measured lengths on its armature (Object.mocap_measured): with several actors each has its own."""


def _is_armature(_self, obj):
    return obj.type == "ARMATURE"


@with_measured_lengths
class MocapSettings(bpy.types.PropertyGroup):
    # ---- capture
    capture_dir: StringProperty(
        name="Capture Folder", subtype="DIR_PATH",
        description="Folder with calibration.toml (or intri.yml + extri.yml) and videos/<camera>.mp4")
    units: EnumProperty(name="Units", items=UNITS, default="auto",
                        description="Length unit of the calibration when the file does not state it")
    camera_count: IntProperty(name="Cameras", default=0, min=0, description="Cameras imported from the capture")
    capture_frames: IntProperty(name="Capture Frames", default=0, min=0, description="Frames in the imported capture")

    # ---- subject
    armature: PointerProperty(name="Armature", type=bpy.types.Object, poll=_is_armature,
                              description="The rigged character to track (a mesh must be skinned to it)")
    every_armature: BoolProperty(
        name="Track Every Armature", default=False,
        description="Several actors: track the scene's armatures ticked below at once, each placed roughly on its "
                    "own person; each is keyed and exported on its own (in the output folder's actors/<armature>/)")
    subject_checked: BoolProperty(name="Checked", default=False, description="The rig check has run")
    subject_dofs: IntProperty(name="DOF", default=0, description="Degrees of freedom the tracker will solve")
    subject_preset: StringProperty(name="Preset", description="Rig naming the bones were matched with")
    subject_problems: StringProperty(name="Problems", description="What stops the rig from being tracked")
    calibrate_frames: IntProperty(name="Calibration Frames", default=20, min=3, soft_max=60,
                                  description="Fit the actor's proportions on this many frames from the start of "
                                              "the tracked range")
    # actor_height, actor_spine, ...: one actor's measured lengths (with_measured_lengths)
    actor_file: StringProperty(name="Actor Calibration", subtype="FILE_PATH",
                               description="actor.json of the calibration (written by Calibrate Actor, or of an "
                                           "earlier take of the same actor)")
    actor_summary: StringProperty(name="Calibrated Proportions", description="Fitted height and segment lengths")
    use_actor: BoolProperty(name="Track with Calibration", default=False,
                            description="Track with the actor's proportions and key the rig with the actor's "
                                        "rotations (root path rescaled to the rig)")
    # on by default: it measured at least as good as the rig on every sample scene (docs/actor-calibration.md)
    fit_actor_build: BoolProperty(name="Fit the Actor's Build", default=True,
                                  description="Before tracking, fit each actor's proportions on the first "
                                              "Calibration Frames of the take (Subject > Actor Calibration) unless "
                                              "a calibration of this capture is loaded (several actors: saved in "
                                              "their result folders); a take shorter than that keeps the rig's. "
                                              "Off: track with the rig's own proportions")

    # ---- tracker
    algorithm: _enum("algorithm")
    likelihood: _enum("likelihood")
    preset: _enum("preset", update=_apply_preset)
    particles: _number("particles", IntProperty, min=1, soft_max=2000)
    iterations: _number("iterations", IntProperty, min=1, soft_max=100)
    seed: _number("seed", IntProperty, min=0)
    refine: BoolProperty(name=OPTIONS["refine"].label, default=OPTIONS["refine"].default == "icp",
                         description=OPTIONS["refine"].choices[0].description)
    smoothing_hz: FloatProperty(name="Smoothing", default=DEFAULT_CUTOFF_HZ, min=0.0, soft_max=12.0, precision=1,
                                description="When the take is solved, low-pass its motion at this many Hz (less "
                                            "jitter; 0: keep every frame as solved). An arm whose wrist moves "
                                            f"faster than {FAST_ARM_FROM:g} m/s keeps its solved angles, so a flung "
                                            "hand is not cut short. The solved poses stay in joints_raw.npz / "
                                            "poses_raw.npz in the output folder")
    foot_lock: BoolProperty(name="Foot Locking", default=True,
                            description="When the take is solved, pin its planted feet to the floor by refitting the "
                                        "legs (no foot sliding or sinking). The take before that stays in "
                                        "joints_unpinned.npz / poses_unpinned.npz in the output folder")
    foot_lock_speed: FloatProperty(name="Threshold", default=CONTACT_SPEED, min=0.01, soft_max=0.5, precision=2,
                                   unit="VELOCITY",
                                   description="A foot near the floor and slower than this is planted (raise it if "
                                               "planted feet still slide, lower it if moving feet stick)")
    backend: _enum("backend")
    background: _enum("background")
    landmarks: _enum("landmarks")
    use_frame_range: BoolProperty(name="Limit Frames", default=False,
                                  description="Track only a range of capture frames (otherwise all of them)")
    frame_start: IntProperty(name="First", default=0, min=0, description="First capture frame to track (0-based)")
    frame_end: IntProperty(name="Last", default=0, min=0, description="Last capture frame to track (inclusive)")
    output_dir: StringProperty(
        name="Output Folder", subtype="DIR_PATH",
        description="Where joints, poses, BVH/FBX, the report and overlays are written")
    resume: BoolProperty(name="Resume", default=False,
                         description="Continue a run whose results are already in the output folder")
    run_on: EnumProperty(name="Run On", items=RUN_ON, default="this",
                         description="Where the take is tracked")
    batch_scope: EnumProperty(name="Send", items=BATCH_SCOPE, default="take",
                              description="What is sent to the processes or the cluster")
    batch_folder: StringProperty(name="Captures", subtype="DIR_PATH",
                                 description="Folder whose sub-folders are captures (a calibration and videos/ "
                                             "each): one take per sub-folder, named after it")
    local_workers: IntProperty(name="Processes", default=0, min=0, soft_max=16,
                               description="Chunks tracked at once, one process each (0: one per two cores, as one "
                                           "tracker keeps two cores busy)")
    scheduler_address: StringProperty(name="Address",
                                      description="The Dask scheduler, e.g. tcp://render01:8786; its workers need "
                                                  "the capture, this .blend and the output folder on shared storage "
                                                  "at the same paths")
    worker_command: StringProperty(name="Worker Command",
                                   description="What runs the add-on's command line on the cluster's workers, e.g. "
                                               "\"/opt/blender/blender --background --command markerless_mocap\" "
                                               "(empty: this Blender's path, the same on every worker)")
    chunk_frames: IntProperty(name="Chunk Frames", default=DEFAULT_CHUNK_FRAMES, min=1, soft_max=5000,
                              description="Frames each chunk keeps: a chunk is one worker's task")

    # ---- run state (written by the Track operator)
    is_tracking: BoolProperty(name="Tracking", default=False)
    # ... and by a take sent to local processes or a cluster (operators/track_batch.py), while it runs
    batch_dir: StringProperty(name="Batch Folder", subtype="DIR_PATH",
                              description="Folder of the running batch (its progress, log and results)")
    chunks_done: IntProperty(name="Chunks Done", default=0)
    chunks_total: IntProperty(name="Chunks", default=0)
    # ... and by Calibrate Actor
    is_calibrating: BoolProperty(name="Calibrating", default=False)
    calibration_progress: FloatProperty(name="Calibration Progress", default=0.0, min=0.0, max=1.0,
                                        subtype="FACTOR")
    calibration_status: StringProperty(name="Calibration Status")
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR")
    status: StringProperty(name="Status")
    preparing: BoolProperty(name="Preparing", default=False,
                            description="The one-off preparation before the first frame is running")
    last_error: StringProperty(name="Last Error")
    backend_used: StringProperty(name="Backend Used",
                                 description="The backend the last Track run chose, and why (also in report.json)")
    frames_solved: IntProperty(name="Frames Solved", default=0)
    frames_total: IntProperty(name="Frames To Solve", default=0)
    seconds_per_frame: FloatProperty(name="Seconds per Frame", default=0.0, precision=2)
    last_output: StringProperty(name="Last Output", subtype="DIR_PATH", description="Result folder of the last run")

    def frame_range(self):
        """Capture frames to track as a range, or None for the whole capture."""
        if not self.use_frame_range:
            return None
        if self.frame_end < self.frame_start:
            from ..core.errors import InputError

            raise InputError(f"the last frame ({self.frame_end}) is before the first ({self.frame_start}); "
                             f"fix the frame range in the Track panel")
        return range(self.frame_start, self.frame_end + 1)

    def tracking_settings(self):
        """The engine's settings for the panel's choices: the same translation as the command line's."""
        return settings_from_choices(self)


classes = (MocapMeasuredLengths, MocapSettings)


@bpy.app.handlers.persistent
def reset_run_state(_file=None):
    """A .blend saved during a run (or by a crashed Blender) must not open as 'tracking': the Track
    button would stay disabled for good."""
    for scene in bpy.data.scenes:
        props = getattr(scene, "mocap", None)
        if props is not None and props.is_calibrating:
            props.is_calibrating = False
            props.calibration_status = ""
        if props is not None and props.is_tracking:
            props.is_tracking = False
            props.preparing = False
            props.status = "The previous run did not finish; its solved frames are in the output folder"
            if props.batch_dir:  # the batch process goes on by itself; its chunks are kept and a rerun resumes
                props.status = (f"The take was sent to be tracked in chunks; its progress and results are in "
                                f"{props.batch_dir} (Track again to resume it and key the result)")
                props.batch_dir = ""


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.mocap = PointerProperty(type=MocapSettings)
    bpy.types.Object.mocap_actor = BoolProperty(
        name="Track", default=True,
        description="With 'Track Every Armature': track this armature as one of the actors (untick a character "
                    "that is only there to receive the motion)")
    bpy.types.Object.mocap_measured = PointerProperty(type=MocapMeasuredLengths)
    bpy.app.handlers.load_post.append(reset_run_state)


def unregister():
    if reset_run_state in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(reset_run_state)
    del bpy.types.Scene.mocap
    del bpy.types.Object.mocap_actor
    del bpy.types.Object.mocap_measured
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
