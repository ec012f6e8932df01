"""How far calibrations missed the actors' true lengths: per scene and segment, calibrated / true - 1 in per cent,
how many of the ten lengths are within 3 %, and each segment's RMS over the scenes. The RMS of the segments past
3 % is what core/actor/measured_lengths.FOOTAGE_MISS_PERCENT ships (the summary's "the footage reads it to ..."); re-run
this after a change to the calibration and update that table and docs/actor-calibration.md ("How well it works").

    .venv/bin/python tools/calibration_accuracy.py ACTOR_JSON:SCENE [ACTOR_JSON:SCENE ...]

ACTOR_JSON: the actor.json of `calibrate` or `track --calibrate` on SCENE, a sample scene whose scene_info.json has
the actor's true lengths (actor, actor2 ... actor10; a scene without them counts its subject's own lengths).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

from landmark_length_bias import true_lengths

LENGTHS = ("height", "spine", "neck", "shoulder_width", "hip_width", "upper_arm", "forearm", "thigh", "shin", "foot")
WITHIN_PERCENT = 3.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="+")
    args = ap.parse_args(argv)
    from markerless_mocap.core.actor.measured_lengths import FOOTAGE_MISS_PERCENT

    names, misses = [], []
    for pair in args.pairs:
        actor_path, scene = (Path(p) for p in pair.split(":"))
        actor = json.loads(actor_path.read_text())
        true = true_lengths(scene, actor["subject_lengths_m"])
        names.append(scene.name)
        misses.append([100.0 * (actor["lengths_m"][k] / true[k] - 1.0) for k in LENGTHS])
    misses = np.array(misses)  # (scenes, lengths)
    print(f"{'length':16s}" + "".join(f"{n:>9s}" for n in names) + f"{'RMS':>9s}")
    rms = np.sqrt(np.mean(misses ** 2, axis=0))
    for j, k in enumerate(LENGTHS):
        print(f"{k:16s}" + "".join(f"{m:+9.1f}" for m in misses[:, j]) + f"{rms[j]:9.2f}")
    within = (np.abs(misses) <= WITHIN_PERCENT).sum(axis=1)
    print(f"{'within 3 %':16s}" + "".join(f"{w:>6d}/{len(LENGTHS)}" for w in within))
    past = {k: round(float(r), 1) for k, r in zip(LENGTHS, rms) if r > WITHIN_PERCENT}
    print(f"RMS past {WITHIN_PERCENT:g} %: {past}; shipped FOOTAGE_MISS_PERCENT: {FOOTAGE_MISS_PERCENT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
