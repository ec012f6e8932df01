"""tools/clothes_likeness.py on walk's shipped result: the actor's own landmarks, the only person in the room, look
like the actor's clothes of the first frames in every view and frame (above the check's threshold), and the table
has a row per frame after the learned ones."""
import numpy as np
from tool_helpers import load_tool

from markerless_mocap.core.tracking.clothes_check import MIN_LIKENESS


def test_walks_own_landmarks_look_like_its_clothes(capsys):
    from pathlib import Path

    scenes = Path(__file__).resolve().parents[1] / "sample_scenes"
    result = scenes / "walk" / "example_result"
    tool = load_tool("clothes_likeness")
    tool.main([str(scenes / "walk"), str(result), "--learn", "3"])
    lines = capsys.readouterr().out.strip().splitlines()
    with np.load(result / "keypoints.npz") as saved:
        n_frames = len(saved["frames"])
    rows = [line for line in lines[1:] if line.split()[0].isdigit()]
    assert len(rows) == n_frames - 3
    values = np.array([float(v) for row in rows for v in row.split()[1:] if v not in ("-",)])
    assert len(values) >= 3 * len(rows) and values.min() > MIN_LIKENESS
    assert lines[-1].startswith("-:") and "median" in lines[-1]
