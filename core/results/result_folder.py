"""The result folder (architecture.md): written after every solved frame, so a run that stops for
any reason keeps what it solved, and `--resume` continues from the checkpoint exactly.

    joints.npz   names, frames, positions (F,J,3) world metres (every bone's head)
    poses.npz    dof_names, frames, poses (F,D)
    joints_raw.npz, poses_raw.npz  once a finished take is smoothed (core/tracking/smoothing.py): the poses as solved;
                 joints.npz and poses.npz then hold the smoothed take
    joints_unpinned.npz, poses_unpinned.npz  once a finished take's feet are locked (core/tracking/foot_lock.py): the
                 take before the locking (smoothed when smoothing is on, else as solved); joints.npz and poses.npz
                 then hold the take with its planted feet pinned, the one the animation files are made from
    keypoints.npz  with learned evidence: frames, cameras, uv (F,C,33,2) image pixels, visibility (F,C,33)
    report.json  settings, seed, per-frame energy, seconds and CPU seconds, totals, software versions
    checkpoint.npz  the tracker's state after the last solved frame (optimiser particles, RNG, colour model) as
                 plain, versioned data (core/tracking/checkpoint.py)
"""
import errno
import json
import platform
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from ..atomic_files import atomic_path
from ..tracking import checkpoint


# Several actors tracked together: one folder in the layout above per armature, OUT/actors/<armature>/
# (docs/several-actors.md).
ACTORS_FOLDER = "actors"


def actor_folder_name(name):
    """A folder name for an armature's name (characters a file system may refuse replaced by _)."""
    return re.sub(r'[<>:"/\\|?*\x00-\x1f]', "_", name).strip(" .") or "armature"


def actor_result_folder(out, folder):
    """Where one actor's files are in a take's result folder `out`: `out` itself for a take of one actor (`folder`
    None), out/actors/<folder> for one of several (`folder`: actor_folder_name of its armature)."""
    return Path(out) if folder is None else Path(out) / ACTORS_FOLDER / folder


class ResultWriteError(OSError):
    """The result folder cannot be written (not writable, disk full...); the message names the folder."""

    def __init__(self, message, errno_code=None):
        super().__init__(message)
        self.errno = errno_code


def _atomic_write(path, write):
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        write(fh)


def require_writable_folder(out):
    """Create the result folder and prove a file can be written in it, or a ResultWriteError naming it."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write_probe"):
            pass
    except OSError as exc:
        raise ResultWriteError(f"the result folder {out} cannot be written ({exc.strerror or exc}); choose another "
                               "result folder, or fix its permissions", exc.errno) from None
    return out


def _cpu_seconds(estimate):
    """The frame's process CPU seconds; None for frames solved before this was recorded (a resumed old run)."""
    value = getattr(estimate, "cpu_seconds", None)
    return None if value is None else float(value)


def _mean_cpu_seconds(estimates):
    values = [v for v in map(_cpu_seconds, estimates) if v is not None]
    return float(np.mean(values)) if values else None


def software_versions():
    import cv2
    import scipy

    versions = {"python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                "scipy": scipy.__version__}
    try:
        import numba

        versions["numba"] = numba.__version__
    except ImportError:
        pass
    return versions


class ResultWriter:
    RAW_FILES = ("joints_raw.npz", "poses_raw.npz")  # the solved take, beside a smoothed joints.npz / poses.npz
    UNPINNED_FILES = ("joints_unpinned.npz", "poses_unpinned.npz")  # the take before its feet were locked

    def __init__(self, out_dir, body, settings, info=None, blender_version=None):
        self.out = require_writable_folder(out_dir)
        self.body = body
        self.settings = settings
        self.info = dict(info or {})
        self.estimates = []
        self.started = time.time()
        self.blender_version = blender_version  # the engine never imports bpy: the caller says

    @property
    def checkpoint_path(self):
        return self.out / checkpoint.FILE_NAME

    @property
    def legacy_checkpoint_path(self):
        """Where releases before the plain checkpoint kept it (read and converted on --resume)."""
        return self.out / checkpoint.LEGACY_FILE_NAME

    def add(self, estimate, tracker_state=None):
        """Write the result files with `estimate` added. If they cannot be written (a full disk...), the
        files keep the frames written before, the estimate is dropped, and a ResultWriteError says so."""
        self.estimates.append(estimate)
        try:
            self.write()
            if tracker_state is not None:
                self._write_checkpoint(tracker_state)
        except OSError as exc:
            self.estimates.pop()
            raise self._write_error(estimate.frame, exc) from None

    def _write_error(self, frame, exc):
        why = "the disk is full" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))
        if self.estimates:
            kept = (f"frames {self.estimates[0].frame}-{self.estimates[-1].frame} ({len(self.estimates)}) "
                    "are saved there; free space and continue with --resume")
        else:
            kept = "no frame was saved; free space or choose another result folder"
        return ResultWriteError(f"could not write frame {frame} to {self.out}: {why}; {kept}", exc.errno)

    def _write_motion(self, poses, joints, suffix=""):
        """joints{suffix}.npz and poses{suffix}.npz for the estimates' frames."""
        frames = np.array([e.frame for e in self.estimates], dtype=np.int64)
        names = np.array(self.body.skeleton.bone_names)
        joints = np.asarray(joints).reshape(len(frames), len(names), 3)
        poses = np.asarray(poses).reshape(len(frames), self.body.n_dof)
        _atomic_write(self.out / f"joints{suffix}.npz",
                      lambda fh: np.savez(fh, names=names, frames=frames, positions=joints))
        _atomic_write(self.out / f"poses{suffix}.npz", lambda fh: np.savez(
            fh, dof_names=np.array(self.body.dof_names), frames=frames, poses=poses))

    def write_smoothed(self, poses, joints, smoothing):
        """The finished take's smoothed poses and joints become poses.npz and joints.npz; the solved ones are
        kept as poses_raw.npz and joints_raw.npz; report.json says how it was smoothed (`smoothing`)."""
        self.write_finished(poses, joints, smoothing=smoothing)

    def write_finished(self, poses, joints, smoothing=None, unpinned=None, foot_locking=None):
        """The finished take's post-processed poses and joints become poses.npz and joints.npz. With `smoothing`
        (how it was smoothed) the solved take is kept as *_raw.npz; with `foot_locking` (core/tracking/foot_lock.py's
        report) the take before the feet were locked, `unpinned` = (poses, joints), is kept as *_unpinned.npz.
        report.json says which was done; the files of the one not done go."""
        est = self.estimates
        if smoothing is not None:
            self._write_motion([e.pose for e in est], [e.joints for e in est], "_raw")
            self.info["smoothing"] = {**smoothing, "raw": list(self.RAW_FILES)}
        else:
            self._drop("smoothing", self.RAW_FILES)
        if foot_locking is not None:
            self._write_motion(*unpinned, "_unpinned")
            self.info["foot_locking"] = {**foot_locking, "unpinned": list(self.UNPINNED_FILES)}
        else:
            self._drop("foot_locking", self.UNPINNED_FILES)
        self._write_all(motion=(poses, joints))

    def _drop(self, key, files):
        self.info.pop(key, None)
        for stale in files:
            (self.out / stale).unlink(missing_ok=True)

    @property
    def holds_smoothed_take(self):
        """Whether the folder's joints.npz / poses.npz are a smoothed take (the solved one in RAW_FILES)."""
        return any((self.out / name).exists() for name in self.RAW_FILES)

    @property
    def holds_finished_take(self):
        """Whether the folder's joints.npz / poses.npz are a post-processed take (smoothed, feet locked or both)."""
        return any((self.out / name).exists() for name in self.RAW_FILES + self.UNPINNED_FILES)

    def write(self, motion=None):
        """Every result file for the estimates so far; `motion`: (poses, joints) to write instead of the
        solved ones (a smoothed take)."""
        est = self.estimates
        if motion is None:  # the solved poses: a smoothing or foot locking of an earlier finish no longer holds
            motion = ([e.pose for e in est], [e.joints for e in est])
            self._drop("smoothing", self.RAW_FILES)
            self._drop("foot_locking", self.UNPINNED_FILES)
        self._write_all(motion)

    def _write_all(self, motion):
        est = self.estimates
        self._write_motion(*motion)
        with_landmarks = [e for e in est if getattr(e, "landmarks", None) is not None]
        if with_landmarks:  # the learned 2D evidence each frame was solved with
            _atomic_write(self.out / "keypoints.npz", lambda fh: np.savez(
                fh, frames=np.array([e.frame for e in with_landmarks], dtype=np.int64),
                cameras=np.array(self.info.get("cameras", [])),
                uv=np.array([e.landmarks for e in with_landmarks]),
                visibility=np.array([e.landmark_visibility for e in with_landmarks])))
        report = {
            "settings": self.settings.to_dict(),
            "seed": self.settings.seed,
            **self.info,
            "frames": [{"frame": e.frame, "energy": e.energy, "seconds": e.seconds, "evaluations": e.evaluations,
                        "cpu_seconds": _cpu_seconds(e)} for e in est],
            "totals": {"frames": len(est), "seconds": float(sum(e.seconds for e in est)),
                       "seconds_per_frame": float(np.mean([e.seconds for e in est[1:]])) if len(est) > 1 else None,
                       "cpu_seconds_per_frame": _mean_cpu_seconds(est[1:]),
                       "wall_seconds": time.time() - self.started},
            "software": {**software_versions(), **({"blender": self.blender_version} if self.blender_version else {})},
        }
        _atomic_write(self.out / "report.json", lambda fh: fh.write(json.dumps(report, indent=1).encode()))

    def _write_checkpoint(self, tracker_state):
        _atomic_write(self.checkpoint_path, lambda fh: checkpoint.write(fh, self.estimates, tracker_state,
                                                                        self.settings.to_dict()))
        self.legacy_checkpoint_path.unlink(missing_ok=True)  # one checkpoint per folder: the current one

    def load_checkpoint(self):
        """(estimates, tracker state) of an earlier run in this folder, or (None, None). A checkpoint.pkl of an
        earlier release is converted to checkpoint.npz. A checkpoint that cannot continue with these settings
        raises a CheckpointError naming the fix."""
        legacy = not self.checkpoint_path.exists()
        path = self.legacy_checkpoint_path if legacy else self.checkpoint_path
        if not path.exists():
            return None, None
        estimates, state, settings = (checkpoint.read_legacy if legacy else checkpoint.read)(path)
        differences = checkpoint.setting_differences(settings, self.settings.to_dict())
        if differences:
            raise checkpoint.CheckpointError(f"{path}: the earlier run used different settings: "
                                             f"{_settings_told(differences)}; resume with the options it used "
                                             f"{_options_told(differences)}or choose another --out")
        self.estimates = list(estimates)
        if legacy:
            try:
                self._write_checkpoint(state)
            except OSError as exc:
                raise self._write_error(self.estimates[-1].frame, exc) from None
        return self.estimates, state


def load_joints(path):
    """joints.npz or gt_joints.npz -> (names list, frames (F,), positions (F,J,3))."""
    with np.load(path) as data:
        return [str(n) for n in data["names"]], data["frames"].astype(np.int64), data["positions"]


def _settings_told(differences):
    return ", ".join(f"{name} {was!r} (this run: {now!r})" for name, (was, now) in differences.items())


def _options_told(differences):
    """The command-line options that give back a checkpoint's settings, e.g. "(--landmarks full) ", where the
    settings that differ are options."""
    from ..tracking.options import OPTIONS

    flags = [f"--{name} {was}" for name, (was, _) in differences.items() if name in OPTIONS and was is not None]
    return f"({' '.join(flags)}) " if flags else ""


__all__ = ["ResultWriter", "ResultWriteError", "atomic_path", "load_joints", "software_versions"]
