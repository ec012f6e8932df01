"""The chunk plan of a take: which frames each chunk tracks, which it keeps, where two are cross-faded.

A take F0..F1 is cut into n = ceil(N / K) chunks whose kept ranges split it as evenly as integers allow (each at most
K frames). Chunk i starts W frames before its kept range (its warm-up: initialised there from the landmarks, as a
take's first frame is, and not kept until it has settled) and runs O frames past it (the overlap the next chunk is
cross-faded with). The rule is written so a JavaScript planner (the Flamenco job type) reproduces it with
Math.ceil / Math.floor on integers; docs/batch.md, "The chunk plan", states it and why W and O are what they are.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError

# docs/batch.md, "Warm-up": frames a chunk needs after its start before it agrees with a take tracked in one piece.
DEFAULT_WARMUP = 10
# docs/batch.md, "The chunk plan": frames two chunks are cross-faded over.
DEFAULT_OVERLAP = 5
# docs/batch.md, "The chunk plan": a few minutes of tracking per chunk; the warm-up and the first-frame search
# are then a few per cent of it.
DEFAULT_CHUNK_FRAMES = 300


class PlanError(InputError):
    """Chunk sizes that cannot make a plan; the message names the value and the rule."""


@dataclass(frozen=True)
class Chunk:
    index: int
    track: tuple  # (first, last) frames the chunk tracks, inclusive, warm-up and overlap included
    keep: tuple  # (first, last) frames this chunk owns in the stitched take, inclusive
    fade_in: int  # the first fade_in frames of `keep` are cross-faded with the previous chunk

    @property
    def name(self):
        """The frame part of the chunk's folder name (core/batch/chunk_folder.py)."""
        return frame_range_name(*self.track)


def frame_range_name(first, last):
    return f"{int(first):06d}-{int(last):06d}"


def _integer(value, what):
    if isinstance(value, bool) or int(value) != value:
        raise PlanError(f"{what} must be a whole number, got {value!r}")
    return int(value)


def plan_chunks(first, last, chunk_frames=DEFAULT_CHUNK_FRAMES, warmup=DEFAULT_WARMUP, overlap=DEFAULT_OVERLAP):
    """The chunks of frames first..last (inclusive), in order."""
    first, last = _integer(first, "the first frame"), _integer(last, "the last frame")
    k_max, w, o = (_integer(chunk_frames, "chunk frames"), _integer(warmup, "warm-up"),
                   _integer(overlap, "overlap"))
    if first < 0:
        raise PlanError(f"frames {first}-{last}: capture frames count from 0")
    if last < first:
        raise PlanError(f"frames {first}-{last}: the last frame comes before the first")
    if k_max < 1:
        raise PlanError(f"chunk frames {k_max}: a chunk keeps at least one frame")
    if w < 0 or o < 0:
        raise PlanError(f"warm-up {w} / overlap {o}: neither can be negative")
    if k_max < 2 * o:
        raise PlanError(f"chunk frames {k_max} with overlap {o}: a chunk must keep at least twice the overlap "
                        f"({2 * o} frames), so each cross-fade lies within one chunk")
    n_frames = last - first + 1
    n = -(-n_frames // k_max)
    starts = [first + (i * n_frames) // n for i in range(n + 1)]
    chunks = []
    for i in range(n):
        keep = (starts[i], starts[i + 1] - 1)
        begin = first if i == 0 else max(first, keep[0] - w)
        end = last if i == n - 1 else min(last, keep[1] + o)
        chunks.append(Chunk(i, (begin, end), keep, 0 if i == 0 else o))
    return chunks


def plan_to_json(first, last, chunk_frames=DEFAULT_CHUNK_FRAMES, warmup=DEFAULT_WARMUP, overlap=DEFAULT_OVERLAP):
    """The plan as plain data: what `plan-chunks --json` prints and the Flamenco planner is compared with."""
    chunks = plan_chunks(first, last, chunk_frames, warmup, overlap)
    return {"frames": [int(first), int(last)], "chunk_frames": int(chunk_frames), "warmup": int(warmup),
            "overlap": int(overlap),
            "chunks": [{"index": c.index, "track": list(c.track), "keep": list(c.keep), "fade_in": c.fade_in,
                        "name": c.name} for c in chunks]}


__all__ = ["Chunk", "DEFAULT_CHUNK_FRAMES", "DEFAULT_OVERLAP", "DEFAULT_WARMUP", "PlanError", "frame_range_name",
           "plan_chunks", "plan_to_json"]
