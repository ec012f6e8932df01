"""Calibration readers against hand-computed values, writer round trips, and error messages."""
import shutil
from pathlib import Path

import numpy as np
import pytest

from markerless_mocap.core.capture.camera import Camera, rodrigues_to_matrix
from markerless_mocap.core.capture.calibration import (CalibrationError, CalibrationNotFoundError, natural_key,
                                                       read_calibration, write_easymocap_calibration,
                                                       write_toml_calibration)

DATA = Path(__file__).parent / "data" / "calibration"
RX90 = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Rodrigues [pi/2, 0, 0]
RZ90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # Rodrigues [0, 0, pi/2]
RY90 = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])  # Rodrigues [0, pi/2, 0]


def by_name(cams):
    return {c.name: c for c in cams}


def pinhole(K, Xc):
    """Hand projection of a camera-frame point, no distortion."""
    return np.array([K[0][0] * Xc[0] / Xc[2] + K[0][2], K[1][1] * Xc[1] / Xc[2] + K[1][2]])


# ---- TOML family -------------------------------------------------------------------------------
def test_anipose_mm_units_and_natural_order():
    cams = read_calibration(DATA / "anipose_mm.toml", units="mm")
    assert [c.name for c in cams] == ["cam_1", "cam_2", "cam_10"]
    c = by_name(cams)
    np.testing.assert_allclose(c["cam_10"].t, [0.1, -0.2, 3.0], atol=1e-12)
    np.testing.assert_allclose(c["cam_10"].project([0, 0, 0]), [960 + 1000 * 0.1 / 3, 540 - 1000 * 0.2 / 3])
    np.testing.assert_allclose(c["cam_2"].R, RX90, atol=1e-12)
    np.testing.assert_allclose(c["cam_2"].center, [0.0, -4.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(c["cam_2"].dist, [-0.1, 0.02, 0.001, -0.002, 0.003])
    np.testing.assert_allclose(c["cam_2"].K, [[1200, 0, 950.5], [0, 1210, 530.25], [0, 0, 1]])
    # pi about y: camera at (0, 0, 2) looking back at the origin, x flipped
    np.testing.assert_allclose(c["cam_1"].R, np.diag([-1.0, 1, -1]), atol=1e-12)
    np.testing.assert_allclose(c["cam_1"].project([0.1, 0, 0]), [640 - 800 * 0.1 / 2, 360], atol=1e-9)
    assert (c["cam_1"].width, c["cam_1"].height) == (1280, 720)


def test_anipose_units_from_metadata_and_default(tmp_path):
    text = (DATA / "anipose_mm.toml").read_text()
    p = tmp_path / "calibration.toml"
    p.write_text(text.replace("adjusted = false", 'units = "mm"\nadjusted = false'))
    np.testing.assert_allclose(by_name(read_calibration(p))["cam_10"].t, [0.1, -0.2, 3.0])
    # without units anipose is read as metres: cameras thousands of metres apart are refused, naming the fix
    with pytest.raises(CalibrationError, match=r"anipose_mm\.toml: the cameras are up to \d+ m apart.*probably in "
                                               r"millimetres read as metres: add units = \"mm\" under \[metadata\]"):
        read_calibration(DATA / "anipose_mm.toml")


def test_pose2sim_four_distortions_float_size_and_matrix_rotation():
    c = by_name(read_calibration(DATA / "pose2sim_calib.toml"))
    a, b = c["cam_01"], c["cam_02"]
    assert (a.width, a.height) == (1088, 1920)  # portrait, floats in the file
    assert a.dist.shape == (4,)
    x, y = 0.5 / 4, 1.0 / 4
    r2 = x * x + y * y
    radial = 1 + 0.01 * r2 - 0.02 * r2 * r2
    np.testing.assert_allclose(a.project([0, 0, 0]), [1500 * x * radial + 543.5, 1500 * y * radial + 959.5], atol=1e-9)
    np.testing.assert_allclose(b.R, RZ90, atol=1e-15)
    # world (1,0,0) -> camera (0,1,0) + (0,0,5)
    np.testing.assert_allclose(b.project([1, 0, 0]), [960, 544 + 1400 * 0.2], atol=1e-9)


def test_freemocap_defaults_to_mm_and_matches_world_position():
    text = (DATA / "freemocap_calibration.toml").read_text()
    import tomllib

    doc = tomllib.loads(text)
    cams = by_name(read_calibration(DATA / "freemocap_calibration.toml"))
    assert set(cams) == {"cam_0", "cam_1"}
    for name, cam in cams.items():
        # the file's own world_position (= -R^T t, mm) must equal our centre in metres
        np.testing.assert_allclose(cam.center, np.array(doc[name]["world_position"]) / 1000, atol=1e-12)
        np.testing.assert_allclose(cam.R.T, doc[name]["world_orientation"], atol=1e-12)
        assert (cam.width, cam.height) == (640, 480)  # from image_size
    np.testing.assert_allclose(cams["cam_1"].t, [1.0, 0.0, 2.5])
    np.testing.assert_allclose(cams["cam_1"].R, RZ90, atol=1e-12)
    # units argument overrides the mm default
    with pytest.raises(CalibrationError, match="probably in millimetres read as metres"):
        read_calibration(DATA / "freemocap_calibration.toml", units="m")


def test_caliscope_nested_tables():
    cams = read_calibration(DATA / "caliscope_camera_array.toml")
    assert [c.name for c in cams] == ["0", "1"]
    np.testing.assert_allclose(cams[1].dist, [-0.05, 0.01, 0, 0, 0, 0.001, 0, 0])
    np.testing.assert_allclose(cams[1].center, [1.0, 0.0, -3.0])
    np.testing.assert_allclose(cams[0].project([0, 0, 0]), [639.5, 359.5])


def test_toml_missing_size_uses_image_sizes(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text((DATA / "caliscope_camera_array.toml").read_text().replace("size = [1280, 720]\n", ""))
    with pytest.raises(CalibrationError, match=r"c\.toml: camera '0' has no 'size'"):
        read_calibration(p)
    cams = read_calibration(p, image_sizes={"0": (1280, 720), "1": (1280, 720)})
    assert cams[0].size == (1280, 720)


# ---- EasyMocap -----------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["folder", "intri.yml", "extri.yml"])
def test_easymocap(which):
    path = DATA / "easymocap" if which == "folder" else DATA / "easymocap" / which
    cams = by_name(read_calibration(path))
    assert list(cams) == ["01", "02"]
    a, b = cams["01"], cams["02"]
    assert a.size == (1920, 1080) and b.size == (640, 480)
    np.testing.assert_allclose(a.dist, [-0.1, 0.01, 0, 0, 0])
    assert b.dist.shape == (4,)
    np.testing.assert_allclose(a.t, [0.2, 0.1, 3.0])
    np.testing.assert_allclose(b.R, RY90, atol=1e-15)
    # world (0,0,1) -> camera (1,0,0) + (0,0,2.5)
    np.testing.assert_allclose(b.project([0, 0, 1]), [320 + 700 * 1 / 2.5, 240], atol=1e-9)
    np.testing.assert_allclose(b.K, [[700, 0, 320], [0, 710, 240], [0, 0, 1]])


def test_easymocap_missing_size(tmp_path):
    shutil.copytree(DATA / "easymocap", tmp_path / "e")
    intri = tmp_path / "e" / "intri.yml"
    intri.write_text(intri.read_text().replace("H_02: 480\nW_02: 640\n", ""))
    with pytest.raises(CalibrationError, match=r"intri\.yml: camera '02' has no H_02/W_02"):
        read_calibration(tmp_path / "e")
    cams = read_calibration(tmp_path / "e", image_sizes={"02": (640, 480)})
    assert by_name(cams)["02"].size == (640, 480)


def test_easymocap_missing_extri(tmp_path):
    shutil.copy(DATA / "easymocap" / "intri.yml", tmp_path / "intri.yml")
    with pytest.raises(CalibrationNotFoundError, match="extri.yml"):
        read_calibration(tmp_path / "intri.yml")


def test_easymocap_rodrigues_and_matrix_must_agree(tmp_path):
    shutil.copytree(DATA / "easymocap", tmp_path / "e")
    extri = tmp_path / "e" / "extri.yml"
    extri.write_text(extri.read_text().replace("data: [ 0., 0., 0. ]", "data: [ 0.3, 0., 0. ]"))
    with pytest.raises(CalibrationError, match="'R_01' and 'Rot_01' disagree"):
        read_calibration(tmp_path / "e")


# ---- Qualisys ------------------------------------------------------------------------------------
def test_qualisys_qca():
    cams = read_calibration(DATA / "qualisys.qca.txt")
    assert [c.name for c in cams] == ["26580", "26581"]  # the Oqus marker camera is left out
    a, b = cams
    assert a.size == (1920, 1088)
    np.testing.assert_allclose(a.K, [[1000, 0, 960], [0, 1010, 544], [0, 0, 1]])
    np.testing.assert_allclose(a.dist, [-0.045, 0.14, 0.0006, -0.0004, 0.0])
    np.testing.assert_allclose(a.center, [1.0, -2.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(a.R, np.diag([1.0, -1, -1]), atol=1e-12)  # identity QTM pose looks down
    assert a.project_with_depth([1.0, -2.0, 0.0])[1] == pytest.approx(1.5)
    # fov_video offset (8, 4) is removed from the principal point: 41472/64 - 8, 23296/64 - 4
    assert b.size == (1280, 720)
    np.testing.assert_allclose(b.K[:2, 2], [640, 360])
    np.testing.assert_allclose(b.center, [0.0, 4.0, 1.2], atol=1e-12)
    np.testing.assert_allclose(b.t, [4.0, 0.0, 1.2], atol=1e-12)
    np.testing.assert_allclose(b.project([0, 4, 0]), [640, 360], atol=1e-9)  # straight below it


def test_qca_rotated_view_is_refused(tmp_path):
    p = tmp_path / "x.qca.txt"
    p.write_text((DATA / "qualisys.qca.txt").read_text().replace(
        'serial="26581" model="Miqus Video" viewrotation="0"', 'serial="26581" model="Miqus Video" viewrotation="90"'))
    with pytest.raises(CalibrationError, match="'26581' has viewrotation=90"):
        read_calibration(p)


# ---- writers -----------------------------------------------------------------------------------
def random_cameras(seed=0, n=4):
    rng = np.random.default_rng(seed)
    cams = []
    for i, nd in zip(range(n), [0, 4, 5, 8]):
        K = np.array([[rng.uniform(500, 2000), 0, rng.uniform(300, 900)], [0, rng.uniform(500, 2000),
                                                                            rng.uniform(200, 600)], [0, 0, 1]])
        cams.append(Camera(f"cam_{[3, 12, 1, 2][i]}", K, rng.normal(scale=0.05, size=nd),
                           rodrigues_to_matrix(rng.normal(size=3)), rng.normal(size=3) * 3, 1280 + i, 720 + 2 * i))
    return cams


def assert_same(a: Camera, b: Camera, tol=1e-9):
    assert a.name == b.name and a.size == b.size
    np.testing.assert_allclose(a.K, b.K, atol=tol, rtol=0)
    if a.dist.size == 0:
        assert not np.any(b.dist)
    else:
        np.testing.assert_allclose(a.dist, b.dist, atol=tol, rtol=0)
    np.testing.assert_allclose(a.R, b.R, atol=tol, rtol=0)
    np.testing.assert_allclose(a.t, b.t, atol=tol, rtol=0)


@pytest.mark.parametrize("units", ["m", "mm", "cm"])
def test_toml_writer_round_trip(tmp_path, units):
    cams = random_cameras(1)
    p = write_toml_calibration(cams, tmp_path / "calibration.toml", units=units)
    back = by_name(read_calibration(p))
    assert list(back) == sorted(back, key=natural_key)
    for c in cams:
        assert_same(c, back[c.name])


def test_toml_writer_escapes_names(tmp_path):
    cams = random_cameras(2, n=1)
    cams[0].name = 'front "left" \\ cam'
    back = read_calibration(write_toml_calibration(cams, tmp_path / "c.toml"))
    assert back[0].name == cams[0].name


def test_easymocap_writer_round_trip(tmp_path):
    cams = random_cameras(3)
    write_easymocap_calibration(cams, tmp_path)
    back = by_name(read_calibration(tmp_path))
    for c in cams:
        assert_same(c, back[c.name])


def test_natural_key():
    assert sorted(["cam_10", "cam_2", "Cam_1", "cam_02b"], key=natural_key) == ["Cam_1", "cam_2", "cam_02b", "cam_10"]


# ---- broken files ------------------------------------------------------------------------------
GOOD = """[cam_0]
name = "A"
size = [640, 480]
matrix = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
rotation = [0.0, 0.0, 0.0]
translation = [0.0, 0.0, 3.0]
"""

BROKEN = [
    ("matrix = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]",
     "matrix = [[800.0, 0.0], [0.0, 800.0], [0.0, 0.0]]",
     r"calibration\.toml: camera 'A' has a 3x2 'matrix'; expected 3x3"),
    ("matrix = [[800.0,", "matrix = [[-800.0,", r"calibration\.toml: camera 'A': focal lengths must be positive"),
    ("rotation = [0.0, 0.0, 0.0]", "rotation = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]",
     r"camera 'A' 'rotation' is not orthonormal"),
    ("rotation = [0.0, 0.0, 0.0]", "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]",
     r"camera 'A' 'rotation' is a reflection"),
    ("rotation = [0.0, 0.0, 0.0]", "rotation = [0.0, 0.0]",
     r"camera 'A' has 2 values in 'rotation'; expected 3 values or 3x3"),
    ("distortions = [0.0, 0.0, 0.0, 0.0, 0.0]", "distortions = [0.0, 0.0, 0.0]",
     r"camera 'A' has 3 values in 'distortions'; expected 0, 4, 5 or 8 values"),
    ("size = [640, 480]", "size = [640, 0]", r"camera 'A' has image size"),
    ("size = [640, 480]", "size = [640, 480]\nfisheye = true",
     r"camera 'A' is a fisheye camera; fisheye lenses are not"),
    ("translation = [0.0, 0.0, 3.0]\n", "", r"camera 'A' has no 'translation'"),
    ("[cam_0]", "[cam_0", r"calibration\.toml: not valid TOML"),
    ("matrix", "intrinsics", r"no camera tables found"),
    ("translation = [0.0, 0.0, 3.0]", 'translation = [0.0, "a", 3.0]', r"camera 'A' has a non-numeric"),
]


@pytest.mark.parametrize("old,new,message", BROKEN)
def test_broken_toml_errors(tmp_path, old, new, message):
    p = tmp_path / "calibration.toml"
    assert old in GOOD
    p.write_text(GOOD.replace(old, new, 1))
    with pytest.raises(CalibrationError, match=message):
        read_calibration(p)


def test_good_toml_reads(tmp_path):
    p = tmp_path / "calibration.toml"
    p.write_text(GOOD)
    assert read_calibration(p)[0].name == "A"


def test_duplicate_names_and_bad_units(tmp_path):
    p = tmp_path / "calibration.toml"
    p.write_text(GOOD + "\n" + GOOD.replace("[cam_0]", "[cam_1]"))
    with pytest.raises(CalibrationError, match="two cameras are named 'A'"):
        read_calibration(p)
    p.write_text(GOOD)
    with pytest.raises(CalibrationError, match="unknown units 'inch'"):
        read_calibration(p, units="inch")


def test_missing_and_unknown_files(tmp_path):
    with pytest.raises(CalibrationNotFoundError, match="no calibration found"):
        read_calibration(tmp_path)
    with pytest.raises(FileNotFoundError):
        read_calibration(tmp_path / "nope.toml")
    (tmp_path / "a.toml").write_text(GOOD)
    (tmp_path / "b.toml").write_text(GOOD)
    with pytest.raises(CalibrationError, match="several calibration files"):
        read_calibration(tmp_path)
    bad = tmp_path / "garbage.qca.txt"
    bad.write_text("<calibration><cameras>")
    with pytest.raises(CalibrationError, match="garbage.qca.txt: not valid XML"):
        read_calibration(bad)
