"""The end-of-take word on the views whose landmarks were left out (core/results/views_without_landmarks.py)."""
import json

import pytest
from scene_helpers import scene_dir

from markerless_mocap.core.results.views_without_landmarks import (frame_spans, views_without_landmarks,
                                                                    views_without_landmarks_message)


def test_frames_become_spans_per_camera_and_rare_ones_are_not_named():
    assert frame_spans([12, 3, 4, 5, 10, 11]) == [(3, 5), (10, 12)]
    assert frame_spans([]) == []
    shared = {"3": ["cam1"], "4": ["cam1", "cam2"], "5": ["cam1"], "9": ["cam1"], "10": ["cam1"], "11": ["cam2"]}
    assert views_without_landmarks(shared, min_frames=3) == {"cam1": [(3, 5), (9, 10)]}
    assert views_without_landmarks(shared, min_frames=2) == {"cam1": [(3, 5), (9, 10)], "cam2": [(4, 4), (11, 11)]}


def test_the_message_names_the_views_and_frames_and_the_fix_for_one_actor():
    report = {"views_shared": {str(f): ["cam2"] for f in (20, 21, 22, 23, 24, 30)}}
    said = views_without_landmarks_message(report)
    assert "cam2 on frames 20-24, 30" in said and "--armature ACTOR --armature OTHER" in said
    several = views_without_landmarks_message(report, actors=2)
    assert "cam2 on frames 20-24, 30" in several and "--armature" not in several
    assert views_without_landmarks_message({}) is None
    assert views_without_landmarks_message({"views_shared": {"4": ["cam1"], "5": ["cam1"]}}) is None  # too few


def test_track_says_where_a_passer_by_took_a_view(tmp_path, capsys):
    """crossing_dev, frames 10-28 (under 20: no actor calibration first): the passer-by walks between the actor
    and cam1, then cam2, hiding most of it; there the landmarks are the passer-by's, the views' agreement drops
    them, and `track` ends saying where."""
    pytest.importorskip("bpy")
    from markerless_mocap.operators.cli import main

    scene, out = scene_dir("crossing_dev"), tmp_path / "r"
    code = main(["track", "--scene", str(scene / "subject.blend"), "--capture", str(scene), "--out", str(out),
                 "--frames", "10-28", "--preset", "preview", "--no-export", "--no-overlays", "--seed", "0"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    named = views_without_landmarks(report.get("views_shared", {}))
    assert set(named) & {"cam1", "cam2"}, report.get("views_shared")
    said = views_without_landmarks_message(report)
    assert said in capsys.readouterr().err
