"""The actor's motion on a character of other proportions (issue 15): rotations as solved, the root path
rescaled, bones never stretched; through a BVH export and re-import in Blender."""
import importlib.util
import json

import numpy as np
import pytest

from rig_helpers import REPO, subject_blend_path

pytestmark = pytest.mark.bpy


def _tool():
    spec = importlib.util.spec_from_file_location("character_check", REPO / "tools" / "character_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("factors,overall", [({}, 1.2 / 1.6657), ({"thigh": 0.8, "shin": 0.75, "spine": 0.8,
                                                                    "upper_arm": 0.7}, 0.72)],
                         ids=["subject scaled to 1.2 m", "other proportions"])
def test_character_keeps_its_bones_and_its_feet_on_the_floor(addon_module_name, bpy_module, tmp_path, factors,
                                                              overall):
    """Walk's true motion (30 frames) keyed onto a smaller character: the BVH re-imports (BVH and FBX) with the character's
    own bone offsets (not the subject's), and its lowest skin point stays within 2.5 cm of the floor
    (median 1.2-1.3 cm: the shoe sole's rounding) whenever the actor's does within 3 cm."""
    from scene_helpers import ground_truth_poses

    from markerless_mocap.core.proportions import Proportions

    _, _, poses, _ = ground_truth_poses("walk")
    report = _tool().check_character(bpy_module, addon_module_name, subject_blend_path(), poses[:30],
                                     Proportions(factors, overall), tmp_path)
    (tmp_path / "report.json").write_text(json.dumps(report))
    assert report["bvh_bones"] >= 30
    assert report["bvh_bone_length_max_error_m"] < 1e-5
    assert report["character_vs_subject_bone_length_max_difference_m"] > 0.05  # its own bones, not the subject's
    assert report["bvh_toe_height_vs_keyed_max_m"] < 1e-5
    assert report["fbx_bones"] >= 30 and report["fbx_bone_length_max_error_m"] < 1e-5
    assert report["fbx_toe_height_vs_keyed_max_m"] < 1e-5
    low = report["character_lowest_skin_above_floor_m"]
    assert -0.025 < low["min"] and low["max"] < 0.025 and abs(low["median"]) < 0.02
    if not factors:  # a uniformly scaled character: the feet are the actor's, scaled (exactly)
        assert report["character_minus_ratio_x_actor_lowest_m_max"] < 1e-5
    assert 1.1 < report["character_height_m"] < 1.3


def test_root_path_is_rescaled_about_the_floor_and_the_first_frame(bpy_module):
    from scene_helpers import ground_truth_poses

    from markerless_mocap.core.proportions import Proportions, character_poses, scaled_body, standing_heights

    body, _, poses, _ = ground_truth_poses("walk")
    small = scaled_body(body, Proportions.uniform(0.75))
    out = character_poses(body, small, poses[:20])
    t, c = poses[:20, body.translation_dofs], out[:, small.translation_dofs]
    floor, hip = standing_heights(body)
    floor_s, hip_s = standing_heights(small)
    assert floor_s == pytest.approx(floor, abs=1e-6) and hip_s / hip == pytest.approx(0.75, rel=1e-3)
    np.testing.assert_allclose(c[0, :2], t[0, :2])                      # starts where the actor starts
    np.testing.assert_allclose(c[:, :2] - c[0, :2], 0.75 * (t[:, :2] - t[0, :2]), rtol=1e-3)  # shorter steps
    np.testing.assert_allclose(out[:, 6:], poses[:20, 6:])                 # rotations as solved
