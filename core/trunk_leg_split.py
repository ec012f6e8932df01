"""Where the hip joints sit between the shoulders and the knees, from the person masks.

The landmark fit does not measure it: its spine / thigh ratio came out 1.00-1.13 of the rig's on eleven scenes
whatever the truth (0.92-1.13; docs/actor-calibration.md). The masks do, once every frame's pose is refitted to
them for each candidate body: lengthening the spine and shortening the thighs by the same length (the height
kept) moves the mismatch to a minimum near the truth. Measured from the rig scaled to the fitted height, seed 0,
the spine's log-change at the masks' minimum against the truth: actor3 -0.06 (-0.04), actor5 -0.03 (-0.02),
actor 0.00 (0.00), actor4 +0.015 (+0.058), actor2 0.00 (+0.039): the right side or none, never the wrong one.
So the split is searched on a grid of such trades (core/mask_line_search.py). Where the best is the grid's end
the masks do not pin the split down (on the real Pose2Sim capture the mismatch kept falling to the end, spine
+9 %: loose clothes and mask edges, not trunk), and the usual split stays.
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
    end (core/mask_line_search.py). mismatch: a list of Proportions -> their mask mismatches (poses refitted for
    each). Returns (t, {grid t: mismatch})."""
    return search_line(start, lambda body, t: traded(body, subject_lengths, t), mismatch, step, reach)
