"""A bug must not read like a set-up mistake. Every error about the user's input derives from one class
(core/errors.py InputError); the command line reports it as the user's (its message, exit 2) and anything else
as a bug (a message that says so, the traceback, exit 70), the same before and during tracking; the operators
say so in Blender and keep the frames solved."""
import importlib
from collections import namedtuple

import numpy as np
import pytest

from markerless_mocap.core.errors import InputError

# every error about the user's capture, calibration, footage, rig, actor file, measured lengths, settings, files
INPUT_ERRORS = [
    ("core.capture.camera", "CameraError"), ("core.capture.calibration", "CalibrationError"),
    ("core.capture.calibration", "CalibrationNotFoundError"), ("core.capture.calibration", "MissingImageSizeError"),
    ("core.capture.frames", "FrameSourceError"), ("core.capture.frames", "VideoNotFoundError"),
    ("core.capture.capture", "CaptureError"), ("core.capture.capture", "CaptureNotFoundError"),
    ("core.body.rig_presets", "RigMappingError"), ("core.body.rig_checks", "RigCheckError"),
    ("core.mocap.clip", "MotionFileError"), ("core.mocap.retarget", "RetargetError"),
    ("core.evidence.errors", "FeatureInputError"), ("core.evidence.learned", "LearnedModelError"),
    ("core.evidence.keypoints", "KeypointMapError"), ("core.optimizers", "UnknownOptimizerError"),
    ("core.tracking.smoothing", "SmoothingError"), ("core.tracking.options", "OptionError"),
    ("core.actor.measured_lengths", "MeasuredLengthError"), ("core.actor.landmark_fit", "ProportionsFitError"),
    ("core.actor.proportions", "ProportionsError"), ("core.actor.actor_file", "ActorFileError"),
    ("core.results.evaluation", "EvaluationError"), ("addon.scene_bridge", "SubjectError"),
    ("core.render", "BackendUnavailableError"), ("core.tracking.checkpoint", "CheckpointError"),
    ("operators.track", "TrackSetupError"), ("operators.export", "ExportError"),
    ("operators.cast_session", "CastError"),
    ("operators.import_capture", "ClipLoadError"), ("core.batch.plan", "PlanError"),
    ("core.batch.chunk_folder", "ChunkError"), ("core.tracking.foot_contact", "FootContactError"),
    ("operators.track_batch", "BatchSetupError"), ("operators.track_batch", "ResultMismatchError"),
    ("core.batch.takes", "TakeListError"),
]
# the engine's own contracts between its parts, and what the machine or the build refuses: raised, they are bugs
# (a ResultWriteError is an OSError: the disk or the folder, reported as the user's like any OSError)
INTERNAL_ERRORS = [
    ("core.energy.likelihood", "LikelihoodError"), ("core.energy.prior", "PriorError"),
    ("core.optimizers.base", "OptimizerInputError"), ("core.optimizers.base", "EnergyOutputError"),
    ("core.optimizers.base", "BudgetExceededError"), ("core.optimizers.icp", "IcpProblemError"),
    ("core.render.reference", "RenderInputError"), ("core.render.rim", "RimInputError"),
    ("core.render.glsl", "GlslInputError"), ("core.results.result_folder", "ResultWriteError"),
    ("addon.gpu_likelihood", "GpuUnavailableError"), ("operators.cmd_build", "BuildFailedError"),
    ("operators.cmd_build", "ZipTooLargeError"),
    ("operators.cmd_track", "ParentGone"),  # --stop-with-parent: the batch worker went; caught, exit 75
]


def _class(module, name):
    return getattr(importlib.import_module(f"markerless_mocap.{module}"), name)


@pytest.mark.bpy
def test_the_users_errors_are_one_family_and_the_engines_contracts_are_not():
    pytest.importorskip("bpy")  # addon/ and operators/ import it
    for module, name in INPUT_ERRORS:
        cls = _class(module, name)
        assert issubclass(cls, InputError) and issubclass(cls, ValueError), f"{module}.{name}"
    for module, name in INTERNAL_ERRORS:
        assert not issubclass(_class(module, name), InputError), f"{module}.{name}"


@pytest.mark.bpy
def test_every_error_class_is_placed_in_one_family():
    """A new error class says whether it is the user's (derive it from InputError) or not: listed above."""
    pytest.importorskip("bpy")
    import pkgutil

    defined = set()
    for package in ("core", "addon", "operators"):
        base = importlib.import_module(f"markerless_mocap.{package}")
        for info in pkgutil.walk_packages(base.__path__, f"{base.__name__}."):
            module = importlib.import_module(info.name)
            defined |= {(info.name.removeprefix("markerless_mocap."), v.__name__) for v in vars(module).values()
                        if isinstance(v, type) and issubclass(v, Exception) and v.__module__ == info.name}
    placed = set(INPUT_ERRORS) | set(INTERNAL_ERRORS) | {("core.errors", "InputError")}
    assert defined - placed == set(), "error classes in neither list"


Estimate = namedtuple("Estimate", "frame pose joints energy seconds evaluations")


class _Session:
    """TrackSession's interface as `track` drives it; `fail` raises at construction or at the second frame."""

    fail_at_start = None
    fail_while_solving = None

    def __init__(self, scene, armature, capture_dir, out_dir, settings, **_kwargs):
        if self.fail_at_start is not None:
            raise self.fail_at_start
        self.out, self.solved, self.keyed = out_dir, [], []
        self.n_total = 3
        self.writer = type("W", (), {"info": {}})()

    @property
    def n_done(self):
        return len(self.solved)

    def solve_next(self):
        if self.solved and self.fail_while_solving is not None:
            raise self.fail_while_solving
        self.solved.append(len(self.solved))
        return Estimate(self.solved[-1], np.zeros(3), np.zeros((1, 3)), 0.5, 0.01, 10)

    def key(self, estimate):
        self.keyed.append(estimate.frame)


@pytest.fixture
def cli_track(bpy_module, monkeypatch, tmp_path):
    """`markerless_mocap track` on a scene with one rig, the session replaced by _Session (and no actor calibration:
    it would track the footage for real)."""
    from rig_helpers import build_armature
    from markerless_mocap.operators import cli, track_session

    build_armature(bpy_module, "cmu_mb_rest.json")
    monkeypatch.setattr(track_session, "TrackSession", _Session)
    monkeypatch.setattr(_Session, "fail_at_start", None)
    monkeypatch.setattr(_Session, "fail_while_solving", None)

    def run(capsys):
        code = cli.main(["track", "--capture", str(tmp_path / "capture"), "--out", str(tmp_path / "out"),
                         "--backend", "numpy", "--no-export", "--no-overlays", "--no-calibrate"])
        return code, capsys.readouterr().err.strip().splitlines()

    return run, tmp_path


@pytest.mark.bpy
def test_an_internal_value_error_on_the_command_line_is_reported_as_a_bug(cli_track, capsys):
    run, tmp_path = cli_track
    _Session.fail_at_start = ValueError("index 7 is out of bounds for axis 0 with size 7")
    code, err = run(capsys)
    assert code == 70  # neither 2 (the user's input) nor 1
    assert err[0].startswith("Traceback") and any("index 7 is out of bounds" in line for line in err[1:-1])
    assert err[-1] == ("markerless_mocap track: Track failed with an internal error (ValueError: index 7 is out of "
                       "bounds for axis 0 with size 7). This is a bug in Markerless Mocap, not a problem with your "
                       "capture, rig or settings; the traceback is in the lines above: please report it")


@pytest.mark.bpy
def test_an_input_error_on_the_command_line_is_the_users_to_fix(cli_track, capsys):
    from markerless_mocap.core.capture.capture import CaptureError

    run, _ = cli_track
    message = "calibration.toml: one camera ('cam1') found; multi-camera tracking needs at least two"
    _Session.fail_at_start = CaptureError(message)
    code, err = run(capsys)
    assert (code, err) == (2, [f"markerless_mocap track: {message}"])  # one line, no traceback, no 'bug'


@pytest.mark.bpy
@pytest.mark.parametrize("user", [True, False])
def test_a_failure_while_tracking_is_told_apart_and_the_frames_solved_are_kept(cli_track, capsys, user):
    from markerless_mocap.core.capture.frames import FrameSourceError

    run, tmp_path = cli_track
    _Session.fail_while_solving = (FrameSourceError("cam2.mp4: frame 1 cannot be read; re-encode the video") if user
                                   else ValueError("operands could not be broadcast together"))
    code, err = run(capsys)
    assert err[-1] == f"1 frames solved and saved in {tmp_path / 'out'} (use --resume to continue)"
    if user:
        assert code == 2 and err[-2] == "markerless_mocap track: cam2.mp4: frame 1 cannot be read; re-encode the video"
        assert not any(line.startswith("Traceback") for line in err)
    else:
        assert code == 70 and "This is a bug in Markerless Mocap" in err[-2]
        assert "ValueError: operands could not be broadcast together" in err[-2]
        assert any(line.startswith("Traceback") for line in err)


@pytest.mark.bpy
def test_check_rig_says_a_bug_is_a_bug(addon_module_name, bpy_module, monkeypatch):
    """Check Rig showed any ValueError as the rig's problem; an internal one now says it is a bug."""
    from rig_helpers import build_armature

    bpy = bpy_module
    build_armature(bpy, "cmu_mb_rest.json")
    bridge = importlib.import_module(f"{addon_module_name}.addon.scene_bridge")
    monkeypatch.setattr(bridge, "find_skinned_mesh", lambda arm, scene: None)

    def broken(*_args, **_kwargs):
        raise ValueError("could not broadcast input array from shape (31,) into shape (30,)")

    monkeypatch.setattr(bridge, "body_from_blender", broken)
    with pytest.raises(RuntimeError, match=r"internal error \(ValueError: could not broadcast.*This is a bug"):
        bpy.ops.mocap.check_subject()
    m = bpy.context.scene.mocap
    assert m.subject_dofs == 0 and "bug" in m.subject_problems
    monkeypatch.setattr(bridge, "body_from_blender",
                        lambda *_a, **_k: (_ for _ in ()).throw(bridge.SubjectError("no mesh is skinned to 'X'")))
    with pytest.raises(RuntimeError, match="no mesh is skinned"):
        bpy.ops.mocap.check_subject()
    assert m.subject_problems == "no mesh is skinned to 'X'"
