"""The actor's hip width from the person masks, each candidate's frames refitted to them.

The landmark fit reads the hip width from BlazePose's hip points, which lie inside the hip joints by an amount
that changes with the build. The masks held at the tracked poses moved it a little; with every candidate's
frames refitted to them, the thighs' outlines set it, near the truth on most builds scanned. The same scans
of the shoulder width and of the forearm do not pin those down, so they stay as calibrated (docs/defaults.md,
"hip_width_by_masks").
"""
from __future__ import annotations

import numpy as np

from .mask_line_search import search_line
from .proportions import Proportions

STEP = 0.03   # log-change between grid points
REACH = 4     # grid points each side: +-12 %, the builds' hips differ from a uniform scale by up to 6 % and the
              # calibrated body's hip width was up to 7.6 % off


def widened(proportions, t):
    """`proportions` with the hip width x exp(t)."""
    factors = dict(proportions.factors)
    factors["hip_width"] = float(factors["hip_width"] * np.exp(t))
    return Proportions(factors, proportions.overall)


def hip_width_by_masks(start, mismatch, step=STEP, reach=REACH):
    """The log-change t of `start`'s hip width whose body the masks match best, 0 where their best is the grid's
    end. mismatch: a list of Proportions -> their mask mismatches (poses refitted for each).
    Returns (t, {grid t: mismatch})."""
    return search_line(start, widened, mismatch, step, reach)
