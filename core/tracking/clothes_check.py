"""The check by clothes: a view whose landmarks outline someone dressed unlike the actor loses them for the frame.

The actor's clothes are learned from the take's first LEARN_FRAMES solved frames, where the subject was placed on
the actor (each view whose landmarks the views' agreement kept gives a signature; core/evidence/appearance.py).
Afterwards each view's landmarks are scored against every learned signature (from any view: a side seen now may
have faced another camera then) and set aside when even the most alike is below MIN_LIKENESS.
"""
from __future__ import annotations

import numpy as np

from ..evidence.appearance import likeness

# the actor's signatures come from this many solved frames from the take's first [DESIGN]
LEARN_FRAMES = 3
# below this Bhattacharyya coefficient against every learned signature a view's landmarks are someone else's
# (docs/defaults.md, "MIN_LIKENESS")
MIN_LIKENESS = 0.3


class ClothesCheck:
    """The actor's learned signatures and the check of each frame's views against them."""

    def __init__(self, min_likeness=MIN_LIKENESS, learn_frames=LEARN_FRAMES):
        self.min_likeness, self.learn_frames = float(min_likeness), int(learn_frames)
        self.exemplars = []  # signatures ({"torso": hist, "thighs": hist})
        self.learned_frames = 0

    @property
    def ready(self):
        return self.learned_frames > 0

    def likeness(self, evidence):
        """(C,) each view's likeness to the actor (NaN where its landmarks outline no clothes or nothing is
        learned yet)."""
        out = np.full(len(evidence), np.nan)
        for c, ev in enumerate(evidence):
            value = likeness(ev.clothes, self.exemplars) if ev.found else None
            if value is not None:
                out[c] = value
        return out

    def unlike(self, evidence):
        """(C,) bool: the views whose landmarks outline someone dressed unlike the actor, and (C,) their likeness.
        None is unlike while no view is like the actor: then the actor, or the light, has changed, not every view's
        person."""
        like = self.likeness(evidence)
        with np.errstate(invalid="ignore"):
            unlike = like < self.min_likeness
            return unlike & np.any(like >= self.min_likeness), like

    def learn(self, evidence, kept):
        """Take the signatures of the views `kept` ((C,) bool: their landmarks were the actor's) while fewer than
        `learn_frames` frames are learned."""
        if self.learned_frames >= self.learn_frames or evidence is None:
            return
        new = [ev.clothes for ev, keep in zip(evidence, kept)
               if keep and ev.found and ev.clothes]
        if new:
            self.exemplars.extend(new)
            self.learned_frames += 1

    def state(self):
        """What a checkpoint keeps (plain data)."""
        return {"learned_frames": self.learned_frames,
                "exemplars": [{k: np.asarray(v) for k, v in ex.items()} for ex in self.exemplars]}

    def restore(self, state):
        """Continue from state() (None: a checkpoint from before the check; the signatures are learned again from
        the next frames)."""
        state = state or {}
        self.learned_frames = int(state.get("learned_frames", 0))
        self.exemplars = [{k: np.asarray(v, dtype=np.float64) for k, v in ex.items()}
                          for ex in state.get("exemplars", [])]
