"""One length of the actor's body read from the person masks: a line search along a move of the body.

A move changes the body by one number t (a log-change of a segment, or a trade between two); every candidate's
calibration frames are refitted to the masks before its mismatch counts (core/actor/body_choice.mask_mismatch),
so the poses do not favour the body they were tracked with. The grid's best point is refined by a parabola
through it and its neighbours. Where the best is the grid's end the masks do not pin the length down (they keep
improving past any plausible change: loose clothes, shadows, mask edges), and the move is not made.
"""
from __future__ import annotations

import numpy as np


def search_line(start, move, mismatch, step, reach):
    """The t of move(start, t) whose body the masks match best, 0 where their best is the grid's end.
    move: (Proportions, t) -> Proportions; mismatch: a list of Proportions -> their mask mismatches.
    The grid is step x (-reach .. reach). Returns (t, {grid t: mismatch})."""
    grid = step * np.arange(-reach, reach + 1)
    costs = np.asarray(mismatch([move(start, t) for t in grid]), float)
    table = {round(float(g), 3): float(c) for g, c in zip(grid, costs)}
    if not pinned_down(table):
        return 0.0, table
    best = int(np.argmin(costs))
    t = float(grid[best])
    below, at, above = costs[best - 1:best + 2]  # the parabola's vertex through the best point and its neighbours
    curvature = below - 2.0 * at + above
    if curvature > 0:
        t += float(np.clip(0.5 * step * (below - above) / curvature, -step, step))
    return t, table


def pinned_down(table):
    """Whether a search's {grid t: mismatch} (keys float, or str as saved in actor.json) has its best inside the
    grid, not at an end."""
    costs = {float(t): cost for t, cost in table.items()}
    return min(costs, key=costs.get) not in (min(costs), max(costs))
