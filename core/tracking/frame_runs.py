"""Runs of consecutive frame numbers: a take's solved frames may have gaps (frames left out, a resumed take), and
a gap is not motion for anything that filters or differentiates along the frames."""
import numpy as np


def consecutive_runs(frames):
    """Index ranges [(start, stop), ...] of runs of consecutive frame numbers."""
    frames = np.asarray(frames, dtype=np.int64)
    if frames.size == 0:
        return []
    breaks = np.nonzero(np.diff(frames) != 1)[0] + 1
    edges = np.concatenate([[0], breaks, [frames.size]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
