"""The actor's height from the person masks, used where it disagrees with the landmarks' by more than their
studio errors together.

The landmark fit reads the height within 1.6 % in a studio but 3-7 % short in cluttered rooms with changing
light (lobby, actor9, actor12). The masks read it better: scanning every segment of the calibrated body by a common
factor (head, hands and the skin's girth kept, since the learned masks run a few per cent fat), with every
candidate's frames refitted to the masks, put the least mismatch near the true height on every rendered scene
with one. Taking that height always tracked worse in the studio (the segments' split no longer matched it), so
it is taken only where the two disagree by more than GATE. Then the landmarks' proportions are set aside as well
and the rig scaled uniformly to the masks' height is the body the masks compare with the rig
(core/actor/body_choice.py), which tracked best over those rooms (docs/defaults.md, "height_by_masks").
"""
from __future__ import annotations

import numpy as np

from .mask_line_search import pinned_down, search_line
from .proportions import Proportions, scaled_body, segment_lengths

STEP = 0.02   # log-change between grid points
REACH = 6     # grid points each side: +-12 %; the landmarks read actor12 7.9 % short, where +-8 % ended the scan
              # still falling
GATE = 0.03   # |masks' height / landmarks' - 1| past which the masks' is taken: about the two's studio errors
              # together (docs/defaults.md, "GATE")


def taller(proportions, s):
    """`proportions` with every segment x exp(s), the overall factor (head, hands, girth) kept."""
    return Proportions({k: float(v * np.exp(s)) for k, v in proportions.factors.items()}, proportions.overall)


def height_by_masks(subject, start, mismatch, step=STEP, reach=REACH):
    """Where the masks put the height of `start` (Proportions of `subject`): a dict with the scan's log-change
    and grid, the start's and the masks' heights (m), and whether the masks' is to be taken (pinned down and
    past GATE). mismatch: a list of Proportions -> their mask mismatches (poses refitted for each)."""
    s, grid = search_line(start, taller, mismatch, step, reach)
    height = segment_lengths(scaled_body(subject, start))["height"]
    masks_height = segment_lengths(scaled_body(subject, taller(start, s)))["height"]
    return {"log_change": s, "grid": grid, "landmark_height_m": height, "masks_height_m": masks_height,
            "taken": bool(pinned_down(grid) and abs(masks_height / height - 1.0) > GATE)}
