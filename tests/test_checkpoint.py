"""The checkpoint as plain, versioned data (core/tracking/checkpoint.py): it reads back equal (arrays, the random
generator's state), an optimiser restored from it continues as the unbroken one, a checkpoint from a newer release
is the user's to resolve (named, with the fix), and a checkpoint.pkl written before core/ was grouped into packages
still resumes."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from markerless_mocap.core.errors import InputError
from markerless_mocap.core.optimizers import PoseSpace, make_optimizer
from markerless_mocap.core.results.result_folder import ResultWriter
from markerless_mocap.core.tracking import checkpoint
from markerless_mocap.core.tracking.settings import FrameEstimate, TrackingSettings

OLD_FOLDER = Path(__file__).resolve().parent / "data" / "checkpoint_before_layout"
# The options that folder was tracked with (frames 0-2 of the walk scene); auto chose the "fast" backend there, and
# the landmark model was the full one (the only one then).
OLD_OPTIONS = ["--seed", "0", "--no-export", "--no-overlays", "--preset", "preview", "--backend", "fast",
               "--landmarks", "full"]
D = 4
# Per optimiser: its own options at a small budget, so each of two frames moves its particles and random generator.
OPTIMIZERS = {"isa": {"n": 20}, "apf": {"n": 20}, "pf": {}, "fsa": {}}


def _space():
    return PoseSpace.with_default_scale(np.full(D, -2.0), np.full(D, 2.0), [f"d{i}" for i in range(D)],
                                        np.zeros(D, dtype=bool))


def _energy(poses):
    return np.sum((poses - 0.3) ** 2, axis=1) / 0.01


def _optimizer(name):
    return make_optimizer(name, _space(), budget=200, seed=3, **OPTIMIZERS[name])


def _estimates():
    """Three frames, the middle one without landmarks and CPU seconds (as a resumed old run has)."""
    rng = np.random.default_rng(0)
    out = []
    for frame in range(3):
        landmarks = None if frame == 1 else rng.normal(size=(2, 33, 2)).astype(np.float32)
        out.append(FrameEstimate(frame, rng.normal(size=D), rng.normal(size=(3, 3)), float(rng.normal()),
                                 float(rng.random()), 40 + frame, landmarks=landmarks,
                                 landmark_visibility=None if landmarks is None else rng.random((2, 33)),
                                 cpu_seconds=None if frame == 1 else float(rng.random())))
    return out


def _write(path, estimates, state, settings=None):
    with open(path, "wb") as fh:
        checkpoint.write(fh, estimates, state, (settings or TrackingSettings()).to_dict())


@pytest.mark.parametrize("name", list(OPTIMIZERS))
def test_a_checkpoint_reads_back_equal_and_the_optimiser_continues_as_the_unbroken_one(tmp_path, name):
    unbroken = _optimizer(name)
    unbroken.start(np.zeros(D))
    history = []
    for _ in range(2):
        history.append(unbroken.track_frame(_energy, history).estimate)
    state = {"optimizer": checkpoint.optimizer_state(unbroken), "anchor": np.eye(3), "history": history,
             "color_model": [None, None], "limb_off_frames": {"left arm": 2}, "next_guide": [3, np.ones((2, D))]}
    estimates = _estimates()
    path = tmp_path / checkpoint.FILE_NAME
    _write(path, estimates, state)

    got_estimates, got, settings = checkpoint.read(path)
    assert settings == checkpoint.plain_settings(TrackingSettings().to_dict())
    arrays = state["optimizer"]["arrays"]
    assert sorted(got["optimizer"]["arrays"]) == sorted(arrays) and len(arrays) > 1  # more than the frame count
    for key, value in arrays.items():
        np.testing.assert_array_equal(got["optimizer"]["arrays"][key], value)
        assert got["optimizer"]["arrays"][key].dtype == value.dtype
    assert got["optimizer"]["random"] == unbroken.random_state()
    json.dumps(got["optimizer"]["random"])  # plain data
    assert got["limb_off_frames"] == {"left arm": 2} and got["color_model"] == [None, None]
    np.testing.assert_array_equal(got["next_guide"][1], np.ones((2, D)))
    for a, b in zip(got["history"], history):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(got_estimates, estimates):
        assert (a.frame, a.energy, a.seconds, a.evaluations, a.cpu_seconds) == (
            b.frame, b.energy, b.seconds, b.evaluations, b.cpu_seconds)
        np.testing.assert_array_equal(a.pose, b.pose)
        np.testing.assert_array_equal(a.joints, b.joints)
        assert (a.landmarks is None) == (b.landmarks is None)
        if b.landmarks is not None:
            np.testing.assert_array_equal(a.landmarks, b.landmarks)
            np.testing.assert_array_equal(a.landmark_visibility, b.landmark_visibility)

    resumed = _optimizer(name)
    checkpoint.restore_optimizer(resumed, got["optimizer"])
    for _ in range(2):
        expected, result = unbroken.track_frame(_energy, history), resumed.track_frame(_energy, history)
        np.testing.assert_array_equal(result.estimate, expected.estimate)
        history.append(expected.estimate)


def test_the_state_of_another_optimiser_is_refused(tmp_path):
    isa = _optimizer("isa")
    isa.start(np.zeros(D))
    with pytest.raises(checkpoint.CheckpointError, match="optimiser 'isa', not of 'apf'"):
        checkpoint.restore_optimizer(_optimizer("apf"), checkpoint.optimizer_state(isa))


def test_a_checkpoint_from_a_newer_release_is_the_users_to_resolve(tmp_path):
    path = tmp_path / checkpoint.FILE_NAME
    _write(path, _estimates(), {"optimizer": None})
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    meta = json.loads(str(arrays["meta"]))
    meta["format"] = checkpoint.FORMAT + 1
    np.savez(path, **{**arrays, "meta": np.array(json.dumps(meta))})
    writer = ResultWriter(tmp_path, None, TrackingSettings())
    with pytest.raises(InputError) as err:
        writer.load_checkpoint()
    assert isinstance(err.value, checkpoint.CheckpointError)
    assert str(err.value) == (f"{path} was written by a newer release of Markerless Mocap (checkpoint format "
                              f"{checkpoint.FORMAT + 1}; this release reads format {checkpoint.FORMAT}): resume it "
                              "with that release or a newer one, or track again without --resume")


def test_a_damaged_checkpoint_is_named(tmp_path):
    path = tmp_path / checkpoint.FILE_NAME
    path.write_bytes(b"half a checkpoint")
    with pytest.raises(checkpoint.CheckpointError) as err:
        checkpoint.read(path)
    assert str(err.value).startswith(f"{path} cannot be read as a checkpoint (")
    assert str(err.value).endswith("track again without --resume, or choose another result folder")


def test_a_state_that_is_not_plain_data_is_a_bug_not_a_user_error(tmp_path):
    with pytest.raises(TypeError, match="checkpoint state state.optimizer: a object is not plain data"):
        _write(tmp_path / checkpoint.FILE_NAME, _estimates(), {"optimizer": object()})


def _old_folder(tmp_path):
    out = tmp_path / "result"
    shutil.copytree(OLD_FOLDER, out)
    settings = TrackingSettings(**{"landmarks": "full", **json.loads((out / "report.json").read_text())["settings"]})
    return out, settings


def test_a_checkpoint_pkl_from_before_the_packages_is_converted(tmp_path):
    out, settings = _old_folder(tmp_path)
    # the message names the setting that differs and the option that gives it back
    with pytest.raises(checkpoint.CheckpointError, match=r"the earlier run used different settings: seed 0 \(this "
                       r"run: 1\); resume with the options it used \(--seed 0\) or choose another --out"):
        ResultWriter(out, None, TrackingSettings(**{**settings.to_dict(), "seed": 1})).load_checkpoint()
    assert (out / "checkpoint.pkl").exists() and not (out / "checkpoint.npz").exists()  # refused: left as it was

    done, state = ResultWriter(out, None, settings).load_checkpoint()
    with np.load(out / "poses.npz") as poses:
        assert [e.frame for e in done] == list(poses["frames"]) == [0, 1, 2]
        np.testing.assert_array_equal(np.stack([e.pose for e in done]), poses["poses"])
    assert state["optimizer"]["name"] == "isa" and state["optimizer"]["arrays"]["particles"].shape == (50, 30)
    assert sorted(state) == ["anchor", "color_model", "history", "limb_off_frames", "next_guide", "optimizer",
                             "reference"]
    assert (out / "checkpoint.npz").exists() and not (out / "checkpoint.pkl").exists()  # converted
    again, same = ResultWriter(out, None, settings).load_checkpoint()
    np.testing.assert_array_equal(same["optimizer"]["arrays"]["particles"], state["optimizer"]["arrays"]["particles"])
    assert same["optimizer"]["random"] == state["optimizer"]["random"]


def test_a_checkpoint_pkl_from_before_the_packages_resumes(tmp_path):
    """`track --resume` on the folder the code before core/ was grouped into packages wrote (walk, frames 0-2):
    frames 0-2 are kept as they were, 3-4 solved near the truth."""
    pytest.importorskip("bpy")
    from scene_helpers import cli_environment, scene_dir

    from markerless_mocap.core.results.evaluation import joint_errors

    out, _ = _old_folder(tmp_path)
    command = [sys.executable, "-m", "markerless_mocap", "track", "--scene", str(scene_dir("walk") / "subject.blend"),
               "--capture", str(scene_dir("walk")), "--out", str(out), "--frames", "0-4", *OLD_OPTIONS, "--resume"]
    run = subprocess.run(command, env=cli_environment(), capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "resuming after frame 2: 3 frames already solved" in run.stderr
    # Three frames were too few to smooth; five are smoothed, so the frames as solved are in the _raw files.
    with np.load(OLD_FOLDER / "poses.npz") as before, np.load(out / "poses_raw.npz") as after:
        assert list(after["frames"]) == [0, 1, 2, 3, 4]
        np.testing.assert_array_equal(after["poses"][:3], before["poses"])
    with np.load(OLD_FOLDER / "joints.npz") as before, np.load(out / "joints_raw.npz") as after:
        np.testing.assert_array_equal(after["positions"][:3], before["positions"])
    frames, errors = joint_errors(out / "joints_raw.npz", scene_dir("walk") / "gt_joints.npz")
    per_frame = 1000 * errors.mean(axis=1)
    print("mean joint error per frame (mm):", np.round(per_frame, 1))
    assert list(frames) == [0, 1, 2, 3, 4] and max(per_frame[3:]) < 40  # the restored state was the right one
    assert (out / "checkpoint.npz").exists() and not (out / "checkpoint.pkl").exists()
    estimates, _, _ = checkpoint.read(out / "checkpoint.npz")
    assert [e.frame for e in estimates] == [0, 1, 2, 3, 4]


def test_a_checkpoint_from_before_a_setting_existed_resumes_as_it_was_tracked():
    """A checkpoint written before `landmarks` existed was tracked with the full model: it resumes with full and is
    refused with heavy (the frames before would not be the heavy model's); `check_clothes` takes the run's value."""
    from markerless_mocap.core.tracking.checkpoint import same_settings, setting_differences
    from markerless_mocap.core.tracking.settings import TrackingSettings

    full = TrackingSettings(landmarks="full")
    old = full.to_dict()
    del old["landmarks"], old["check_clothes"]
    assert same_settings(old, full.to_dict())
    assert same_settings(old, TrackingSettings(landmarks="full", check_clothes=False).to_dict())
    assert not same_settings(old, TrackingSettings(landmarks="heavy").to_dict())
    assert not same_settings(full.to_dict(), TrackingSettings(landmarks="heavy").to_dict())
    # heavy became the default after: resuming such a run with the defaults is refused, naming the option to add
    assert setting_differences(old, TrackingSettings().to_dict()) == {"landmarks": ("full", "heavy")}
