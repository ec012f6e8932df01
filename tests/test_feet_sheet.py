"""tools/feet_sheet.py: the feet of a result drawn over its footage, and how far pinned contacts move in the images.
On walk's bundled result (default settings, foot locking on) a pinned foot point stays within a few pixels over its
contact in every view, and less than the same point before locking (tools/feet_sheet.py on it: locked 1.0-2.1 px,
unpinned 2.4-4.3 px)."""
import json
from pathlib import Path

import cv2
import numpy as np
from tool_helpers import load_tool

REPO = Path(__file__).resolve().parents[1]
WALK = REPO / "sample_scenes" / "walk"


def _tool():
    return load_tool("feet_sheet")


def test_pinned_contacts_stay_put_in_the_images_and_move_less_than_unpinned():
    from markerless_mocap.core.capture.calibration import read_calibration

    tool = _tool()
    result = WALK / "example_result"
    frames, locked = tool.load_points(result / "joints.npz")
    _, unpinned = tool.load_points(result / "joints_unpinned.npz", frames)
    report = json.loads((result / "report.json").read_text())
    cameras = read_calibration(WALK)
    drift = tool.contact_drift(report, cameras, frames, locked, unpinned)
    assert len(drift) >= 4
    assert max(row["locked"] for row in drift) < 4.0
    # held still: 1.5 px on average against 2.0 unpinned (the walk's six held contacts)
    assert np.mean([row["locked"] for row in drift]) < 0.8 * np.mean([row["unpinned"] for row in drift])
    following = {"foot_locking": {"contacts": report["foot_locking"]["following_their_path"]}}
    for row in tool.contact_drift(following, cameras, frames, locked, unpinned):  # their jitter goes
        assert row["locked"] < 0.8 * row["unpinned"], row


def test_the_sheet_has_a_row_per_frame_shown(tmp_path):
    out = tmp_path / "feet.png"
    assert _tool().main([str(WALK / "example_result"), str(WALK), "--out", str(out), "--every", "10",
                         "--frames", "10-40", "--views", "cam1,cam3"]) == 0
    sheet = cv2.imread(str(out))
    assert sheet is not None and sheet.shape[0] == 4 * 240   # frames 10, 20, 30, 40 at 240 px a row
