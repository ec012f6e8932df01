"""Real motion in the body's DOF space: training data for the anatomical prior and the AR dynamics.

The bundled CMU clips (core/data/motion) are resampled to the capture rate, retargeted onto the
user's armature and fitted with its DOF (core/mocap/to_dof.py). That costs tens of seconds, so the
result is cached per rig (keyed by the rest skeleton and the DOF layout) in the user cache folder
(MOCAP_CACHE_DIR, else ~/.cache/markerless_mocap).

The pose excerpts (core/data/poses) are single moments of many more kinds of motion (dance, martial
arts, acrobatics, getting up, everyday actions): they widen the prior's density, and since they are
not continuous motion they never train the dynamics.

`exclude` leaves out a window of a clip (in frames at the capture rate), so a sample scene made from
that clip is never tracked with a prior that has seen its own poses.
"""
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ..atomic_files import atomic_path
from ..mocap.bvh import read_bvh
from ..mocap.to_dof import dof_sequence_from_clip

MOTION_DIR = Path(__file__).resolve().parents[1] / "data" / "motion"
POSES_DIR = Path(__file__).resolve().parents[1] / "data" / "poses"
EXCLUDE_MARGIN = 15  # frames kept away on each side of an excluded window


def cache_dir():
    env = os.environ.get("MOCAP_CACHE_DIR")
    path = Path(env) if env else Path.home() / ".cache" / "markerless_mocap"
    path.mkdir(parents=True, exist_ok=True)
    return path


def _body_key(body, extra):
    h = hashlib.sha1()
    h.update(np.round(body.skeleton.rest, 5).tobytes())
    h.update(np.round(body.skeleton.armature_matrix, 5).tobytes())
    h.update("|".join(body.dof_names).encode())
    for d in body.dofs:
        for t in d.targets:
            h.update(np.round(np.asarray(t.axis_local), 6).tobytes())
    h.update(json.dumps(extra, sort_keys=True).encode())
    return h.hexdigest()[:16]


def clip_windows(n_frames, exclude, length, stride):
    """Start frames of training windows of `length` frames that avoid the excluded window."""
    starts = []
    lo, hi = exclude if exclude else (n_frames, n_frames)
    lo, hi = lo - EXCLUDE_MARGIN, hi + EXCLUDE_MARGIN
    for s in range(0, max(1, n_frames - length + 1), stride):
        if s + length <= lo or s >= hi:
            starts.append(s)
    return starts


def training_sequences(body, fps=30.0, exclude=None, window=40, stride=30, max_windows=10, clips=None,
                       progress=None):
    """List of (T,D) pose sequences at `fps` from the bundled clips (cached per rig).

    exclude: {clip file stem: (first, last)} frames at `fps` to leave out.
    progress(fraction, text): called as each clip is mapped onto the rig (not when the cache is hit).
    """
    exclude = dict(exclude or {})
    paths = sorted(MOTION_DIR.glob("*.bvh")) if clips is None else [Path(p) for p in clips]
    key = _body_key(body, {"fps": fps, "exclude": exclude, "window": window, "stride": stride,
                           "max": max_windows, "clips": [p.name for p in paths], "version": 1})
    cached = cache_dir() / f"motion_{key}.npz"
    if cached.exists():
        with np.load(cached) as data:
            return [data[k] for k in sorted(data.files, key=lambda k: int(k.split("_")[1]))]
    sequences = []
    for i, path in enumerate(paths):
        if progress is not None:
            progress(i / max(1, len(paths)), f"mapping motion clip {i + 1} of {len(paths)} onto the rig")
        clip = read_bvh(path).resample(fps)
        starts = clip_windows(clip.n_frames, exclude.get(path.stem), window, stride)
        if len(starts) > max_windows:
            starts = [starts[i] for i in np.linspace(0, len(starts) - 1, max_windows).round().astype(int)]
        for s in starts:
            poses, _ = dof_sequence_from_clip(body, clip, frames=np.arange(s, s + window))
            sequences.append(poses)
    with atomic_path(cached) as tmp:
        np.savez(tmp, **{f"seq_{i}": s for i, s in enumerate(sequences)})
    return sequences


def excerpt_poses(body, paths=None, progress=None):
    """(N,D) poses of the pose excerpts (POSES_DIR) on this body, cached per rig like the clips."""
    paths = sorted(POSES_DIR.glob("*.bvh")) if paths is None else [Path(p) for p in paths]
    if not paths:
        return np.zeros((0, len(body.dof_names)))
    key = _body_key(body, {"excerpts": [hashlib.sha1(p.read_bytes()).hexdigest() for p in paths], "version": 1})
    cached = cache_dir() / f"poses_{key}.npy"
    if cached.exists():
        return np.load(cached)
    poses = []
    for i, path in enumerate(paths):
        if progress is not None:
            progress(i / len(paths), f"mapping pose excerpt {i + 1} of {len(paths)} onto the rig")
        poses.append(dof_sequence_from_clip(body, read_bvh(path))[0])
    poses = np.concatenate(poses)
    with atomic_path(cached) as tmp:
        np.save(tmp, poses)
    return poses


def scene_exclusion(capture_folder):
    """For the bundled sample scenes: the clip window the scene was made from (scene_info.json)."""
    info_path = Path(capture_folder) / "scene_info.json"
    if not info_path.exists():
        return None
    info = json.loads(info_path.read_text())
    try:
        stem = Path(info["source"]).stem
        first = int(info["first_source_frame_30fps"])
        return {stem: (first, first + int(info["n_frames"]) - 1)}
    except (KeyError, ValueError):
        return None


def fit_dynamics(body, sequences, gamma=0.8):
    """Linear AR(3) per joint DOF fitted on the sequences; damped constant velocity for the root
    (its position and heading are not predictable from how people move their joints)."""
    from ..optimizers.dynamics import LinearAR3

    ar = LinearAR3.fit(sequences, min_sigma=1e-3)
    root = np.concatenate([body.translation_dofs, body.root_rotation_dofs])
    coeffs, offset, sigma = ar.coeffs.copy(), ar.offset.copy(), ar.sigma.copy()
    coeffs[root] = [1.0 + gamma, -gamma, 0.0]
    offset[root] = 0.0
    sigma[root] = 0.5 * body.scale[root]
    return LinearAR3(coeffs, offset, sigma)


def build_motion_models(body, fps=30.0, exclude=None, seed=0, n_samples=200, progress=None, poses=False):
    """(anatomical prior, AR(3) dynamics) trained on the bundled clips mapped onto this body; the prior
    also on the pose excerpts when poses=True.

    progress(fraction, text), fraction in [0, 1]: the clips take most of the time the first time a rig
    is seen; after that they come from the cache."""
    from ..energy.prior import AnatomicalPrior

    report = progress or (lambda fraction, text: None)
    clips_share = 0.7 if poses else 0.9  # of the progress bar; the excerpts, when used, take the rest up to 0.9
    sequences = training_sequences(body, fps=fps, exclude=exclude,
                                   progress=lambda f, text: report(clips_share * f, text))
    excerpts = excerpt_poses(body, progress=lambda f, text: report(0.7 + 0.2 * f, text)) if poses else None
    report(0.9, "fitting the anatomical prior and the dynamics")
    training = np.concatenate(sequences if excerpts is None else sequences + [excerpts])
    prior = AnatomicalPrior.fit(training, body.prior_groups, n_samples=n_samples, seed=seed)
    prior.bounded_by(body.lower, body.upper)
    return prior, fit_dynamics(body, sequences)
