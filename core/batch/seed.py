"""Where each chunk starts: the person followed from the take's first frame by the landmarks alone.

A take's first frame is searched around the subject as the user placed it in the .blend: where the person stands
when the take begins. A chunk that begins later would be searched there too, and by then the person may have
walked metres away; with other people in the footage the search can settle on one of them and follow them for the
whole chunk (docs/batch.md, "Warm-up": busy from frame 45, 2 m off throughout). So before the chunks, one pass
follows the person from the take's start: each followed frame's landmark crops are placed around the last frame's
fit, and the body is fitted to the triangulated landmarks (core/tracking/first_frame.keypoint_start), no search.
It visits every SEED_STRIDE-th frame and each chunk's first frame; a chunk then starts its first-frame search (the
landmarks, then ISA) around the pass's pose at its first frame instead of the placement.

    CHUNKS/<take>/seeds-<F0:06d>-<F1:06d>_<key>.npz   frames (S,), poses (S,D), fitted (S,) bool
    CHUNKS/<take>/seeds-<F0:06d>-<F1:06d>_<key>.so-far.npz   the same up to the last chunk start reached, while the
                                                           pass runs: each chunk may start as soon as its frame is in
    CHUNKS/<take>/seeds-<F0:06d>-<F1:06d>_<key>.<actor>.npz  per actor of a take of several, all followed together
"""
from __future__ import annotations

import glob
from pathlib import Path

import numpy as np

from ..atomic_files import atomic_path
from ..energy.likelihood import default_pose_at
from ..tracking.first_frame import keypoint_start
from .plan import frame_range_name

# A walking person moves about 0.25 m in 5 frames at 30 fps, well inside the landmark crops (1.35 x the body around
# the last fit) [DESIGN]; docs/batch.md, "Where a chunk starts: the seeds", has the pass's cost.
SEED_STRIDE = 5


def seed_frames(first, starts, stride=SEED_STRIDE):
    """The frames the pass visits: every `stride`-th from `first` up to the last chunk start, and each start."""
    last = max([first, *starts])
    return sorted(set(range(first, last + 1, max(1, int(stride)))) | {int(s) for s in starts} | {first})


def follow_actors(trackers, frames, placements, progress=None, starts=(), reached=None):
    """(frames, [poses (S,D)], [fitted (S,) bool]) of each actor (one tracker and placement each, the subject as
    placed) followed over `frames` (ascending) with its tracker's landmark evidence, from its placement at the first
    of them, which is kept as it is: a chunk that starts there starts as `track` does. Where the landmarks do not
    place a body, its last pose is carried on. With several actors each is fitted in turn with the others' bodies
    set apart where they were just followed (core/tracking/other_actors.py), so a landmark of the person beside it
    is not taken for its own. `reached(frames, poses, fitted)` is called with what is followed so far at each of
    `starts` (the chunks' first frames), so their chunks can begin before the pass ends."""
    from ..tracking.other_actors import OtherActor, OtherActors

    starts = {int(s) for s in starts}
    guides = [np.asarray(p, dtype=np.float64) for p in placements]
    for tracker, guide in zip(trackers, guides):
        tracker.energy.set_reference_pose(default_pose_at(tracker.body, guide))
    poses, fitted = [[g.copy()] for g in guides], [[False] for _ in guides]
    for i, frame in enumerate(frames[1:], 1):
        for a, tracker in enumerate(trackers):
            if len(trackers) > 1:
                tracker.set_others(OtherActors([OtherActor(t.body, t.proxy, guides[b], t.energy.rig_points)
                                                for b, t in enumerate(trackers) if b != a]))
            tracker.load_frame(frame, guides[a])
            pose, _fit = keypoint_start(tracker.body, tracker.capture.cameras, tracker.energy, guides[a])
            if pose is not None:
                guides[a] = np.asarray(pose, dtype=np.float64)
            poses[a].append(guides[a].copy())
            fitted[a].append(pose is not None)
        if progress is not None:
            progress(i, len(frames) - 1, frame)
        if reached is not None and int(frame) in starts:
            reached(np.asarray(frames[:i + 1], dtype=np.int64), [np.array(p) for p in poses],
                    [np.array(f) for f in fitted])
    return np.asarray(frames, dtype=np.int64), [np.array(p) for p in poses], [np.array(f) for f in fitted]


def seeds_path(chunks_root, take, first, last, key, actor=None):
    """The finished pass's file (`actor`: the folder name of one of several actors, each followed into a file of
    its own); while it runs, what it has followed so far is in so_far_path(...)."""
    return Path(chunks_root) / take / f"seeds-{frame_range_name(first, last)}_{key}{_actor_suffix(actor)}.npz"


def _actor_suffix(actor):
    return "" if actor is None else f".{actor}"


def so_far_path(path):
    return Path(path).with_name(Path(path).stem + ".so-far.npz")


def write_seeds(path, frames, poses, fitted):
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, frames=frames, poses=poses, fitted=fitted)
    return path


def find_seed(chunks_root, take, key, frame, actor=None):
    """The followed pose at `frame` from a seeds file of this take, key and actor, or None when none holds that
    frame."""
    mine = glob.escape(f"_{key}{_actor_suffix(actor)}")
    for pattern in (f"seeds-*{mine}.npz", f"seeds-*{mine}.so-far.npz"):  # finished, then so far
        for path in sorted((Path(chunks_root) / take).glob(pattern)):
            try:
                with np.load(path) as data:
                    hit = np.nonzero(data["frames"] == int(frame))[0]
                    if hit.size:
                        return data["poses"][hit[0]].copy()
            except (OSError, ValueError, KeyError):
                continue
    return None


__all__ = ["SEED_STRIDE", "find_seed", "follow_actors", "seed_frames", "seeds_path", "so_far_path", "write_seeds"]
