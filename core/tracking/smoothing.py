"""Temporal smoothing of a solved take: a zero-phase low-pass filter over each degree of freedom.

Each frame is solved on its own evidence, so the solved poses jitter from frame to frame. A Butterworth
low-pass (2nd order, run forwards and backwards: 4th order, no lag) at DEFAULT_CUTOFF_HZ brings the joints'
acceleration to about the true motion's and lowers the mean joint error a little on every sample scene; lower
cut-offs start cutting real motion (docs/defaults.md, "DEFAULT_CUTOFF_HZ").

It works on the DOF vectors, so every bone keeps its length; the joint angles stay within their limits; the
root orientation is filtered as a unit quaternion with a consistent sign (a rotation vector jumps where the
turn passes 180 degrees). Runs of consecutive frames are filtered apart: a gap in the frame numbers is not
motion. It is offline (it needs the frames after each frame), so it runs once the take is solved; the raw
poses are kept beside the smoothed ones. An arm whose hand moves faster than the filter can follow keeps its
solved angles for those frames (core/tracking/fast_arms.py).
"""
from __future__ import annotations

import numpy as np

from ..body.rotations import quaternions_to_rotvecs, rotvecs_to_quaternions
from ..errors import InputError
from .fast_arms import keep_fast_arms
from .frame_runs import consecutive_runs

DEFAULT_CUTOFF_HZ = 8.0
ORDER = 2  # per pass; forwards and backwards make it 4th order with zero phase
MIN_RUN = 4  # shorter runs of consecutive frames stay as solved


class SmoothingError(InputError):
    """The cut-off cannot be applied at this frame rate."""


def check_cutoff(cutoff_hz, fps):
    """The cut-off as a fraction of the Nyquist frequency, or a SmoothingError naming the fix."""
    cutoff_hz, fps = float(cutoff_hz), float(fps)
    if not np.isfinite(cutoff_hz) or cutoff_hz <= 0:
        raise SmoothingError(f"smoothing cut-off {cutoff_hz:g} Hz: give a positive frequency (or 0 to turn "
                             "smoothing off)")
    if not np.isfinite(fps) or fps <= 0:
        raise SmoothingError(f"the footage's frame rate ({fps:g}) is unknown: smoothing needs it; turn smoothing "
                             "off (0 Hz)")
    nyquist = fps / 2
    if cutoff_hz >= nyquist:
        raise SmoothingError(f"smoothing cut-off {cutoff_hz:g} Hz is not below half the frame rate "
                             f"({nyquist:g} Hz at {fps:g} fps); choose less than {nyquist:g} Hz, or 0 to turn it off")
    return cutoff_hz / nyquist


def low_pass(signal, cutoff_fraction):
    """Zero-phase Butterworth low-pass of each column of `signal` (F, N) along the frames."""
    from scipy.signal import butter, filtfilt

    b, a = butter(ORDER, cutoff_fraction)
    # Padding by reflection about the end values (odd): the ends keep their level and slope, not zero.
    pad = min(3 * max(len(a), len(b)), len(signal) - 1)
    return filtfilt(b, a, signal, axis=0, padtype="odd", padlen=pad)


def smooth_poses(body, poses, frames, fps, cutoff_hz=DEFAULT_CUTOFF_HZ, fast_arms=True):
    """Solved poses (F,D) of `frames` (F,) -> the smoothed poses (F,D), each run of consecutive frames low-passed
    at `cutoff_hz`; runs shorter than MIN_RUN frames unchanged. The joint angles are clipped to their limits.
    With `fast_arms`, an arm keeps its solved angles where its wrist moves fast (core/tracking/fast_arms.py)."""
    poses = np.asarray(poses, dtype=np.float64)
    fraction = check_cutoff(cutoff_hz, fps)
    out = poses.copy()
    rot = np.asarray(body.root_rotation_dofs, dtype=np.int64)
    rest = np.setdiff1d(np.arange(poses.shape[1]), rot)
    for a, b in consecutive_runs(frames):
        if b - a < MIN_RUN:
            continue
        run = poses[a:b]
        out[a:b, rest] = low_pass(run[:, rest], fraction)
        if rot.size:
            q = low_pass(rotvecs_to_quaternions(run[:, rot]), fraction)
            out[a:b, rot] = quaternions_to_rotvecs(q, run[:, rot])
    out[:, rest] = np.clip(out[:, rest], body.lower[rest], body.upper[rest])
    if fast_arms:
        out = keep_fast_arms(body, poses, out, frames, fps)
    return out
