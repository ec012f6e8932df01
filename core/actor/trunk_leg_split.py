"""Where the hip joints sit between the shoulders and the knees, from the person masks.

The landmark fit does not measure it: its spine / thigh ratio comes out near the usual split whatever the truth.
The masks do, once every frame's pose is refitted to them for each candidate body: lengthening the spine and
shortening the thighs by the same length (the height kept) moves the mismatch to a minimum on the truth's side
or at no change, never the wrong side (docs/defaults.md, "split_by_masks"). So the split is searched on a grid
of such trades (core/actor/mask_line_search.py). Where the best is the grid's end the masks do not pin the split
down (loose clothes and mask edges, not trunk), and the usual split stays.
"""
from __future__ import annotations

import numpy as np

from .mask_line_search import search_line
from .proportions import Proportions

STEP = 0.03        # spine log-change between grid points
REACH = 3          # grid points each side of the start: +-9 %, beyond what the builds measured needed (6 %)


def traded(proportions, subject_lengths, t):
    """`proportions` with the spine lengthened by exp(t) and each thigh shortened by the length the spine gained
    (t < 0: the reverse), so the standing height stays. subject_lengths: the rig's segment_lengths."""
    factors = dict(proportions.factors)
    gained = subject_lengths["spine"] * factors["spine"] * (np.exp(t) - 1.0)
    factors["spine"] *= float(np.exp(t))
    for key in [k for k in factors if k.endswith("thigh")]:
        thigh = subject_lengths[key if key in subject_lengths else "thigh"]
        factors[key] = float(factors[key] - gained / thigh)
    return Proportions(factors, proportions.overall)


def split_by_masks(start, subject_lengths, mismatch, step=STEP, reach=REACH):
    """The trade t of `start` (Proportions) whose body the masks match best, 0 where their best is the grid's
    end (core/actor/mask_line_search.py). mismatch: a list of Proportions -> their mask mismatches (poses refitted for
    each). Returns (t, {grid t: mismatch})."""
    return search_line(start, lambda body, t: traded(body, subject_lengths, t), mismatch, step, reach)
