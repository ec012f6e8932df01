"""Calibrations that cannot be right: NaN or infinite numbers, a length unit off by 1000, fewer than two
cameras, missing fields, a format the readers do not know. Each is a CalibrationError whose one-line
message names the file, the problem and the fix."""
import math
from pathlib import Path

import numpy as np
import pytest

from markerless_mocap.core.capture.camera import Camera, rodrigues_to_matrix
from markerless_mocap.core.capture.calibration import (CalibrationError, read_calibration,
                                                       write_easymocap_calibration, write_toml_calibration)
from markerless_mocap.core.capture.capture import load_capture

K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])


def two_cameras(distance_m=2.0):
    """Two cameras `distance_m` apart, both 3 m from the origin and looking at it."""
    half = distance_m / 2
    return [Camera("left", K, [], rodrigues_to_matrix([0, 0, 0]), [half, 0, 3.0], 640, 480),
            Camera("right", K, [], rodrigues_to_matrix([0, 0, 0]), [-half, 0, 3.0], 640, 480)]


def one_line(exc_info):
    text = str(exc_info.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_translation_in_toml(tmp_path, bad):
    p = write_toml_calibration(two_cameras(), tmp_path / "calibration.toml")
    assert "translation = [-1.0," in p.read_text()
    p.write_text(p.read_text().replace("translation = [-1.0,", f"translation = [{bad},", 1))  # TOML's nan, inf, -inf
    with pytest.raises(CalibrationError) as err:
        read_calibration(p)
    assert "camera 'right' has NaN or infinite values in 'translation'; " in one_line(err)
    assert "recalibrate, or correct the value" in str(err.value)


def test_non_finite_values_in_easymocap_and_qualisys(tmp_path):
    cams = two_cameras()
    cams[1].t = np.array([np.nan, 0.0, 3.0])  # the writer keeps what it is given
    write_easymocap_calibration(cams, tmp_path / "em")
    with pytest.raises(CalibrationError) as err:
        read_calibration(tmp_path / "em")
    assert "camera 'right' has NaN or infinite values in its translation" in one_line(err)
    qca = (Path(__file__).parent / "data" / "calibration" / "qualisys.qca.txt").read_text()
    broken = tmp_path / "broken.qca.txt"
    assert '<transform x="1000.0"' in qca
    broken.write_text(qca.replace('<transform x="1000.0"', '<transform x="nan"', 1))
    with pytest.raises(CalibrationError) as err:
        read_calibration(broken)
    assert "NaN or infinite" in one_line(err)


def test_millimetres_read_as_metres_are_refused(tmp_path):
    p = write_toml_calibration(two_cameras(2000.0), tmp_path / "calibration.toml")  # 2 m written as 2000 "m"
    with pytest.raises(CalibrationError) as err:
        read_calibration(p)
    assert one_line(err) == ('calibration.toml: the cameras are up to 2000 m apart, more than any capture room; the '
                             'file is probably in millimetres read as metres: add units = "mm" under [metadata] in the '
                             'file (or choose Units: mm when importing)')
    cams = read_calibration(p, units="mm")  # the fix the message names works
    assert np.linalg.norm(cams[0].center - cams[1].center) == pytest.approx(2.0)


def test_metres_read_as_millimetres_are_refused(tmp_path):
    write_easymocap_calibration(two_cameras(2.0), tmp_path)
    with pytest.raises(CalibrationError) as err:
        read_calibration(tmp_path, units="mm")  # 2 m apart read as 2 mm
    assert one_line(err).startswith("intri.yml: the cameras are all within 2.0 mm of each other; the file is "
                                    "probably in metres read as millimetres: choose Units: m")
    assert len(read_calibration(tmp_path)) == 2


def test_a_capture_with_one_camera_is_refused(tmp_path):
    write_toml_calibration(two_cameras()[:1], tmp_path / "calibration.toml")
    (tmp_path / "videos").mkdir()
    with pytest.raises(CalibrationError) as err:
        load_capture(tmp_path)
    assert one_line(err) == ("calibration.toml: one camera ('left') found; multi-camera tracking needs at least two "
                             "calibrated cameras: calibrate every camera of the take into one file")


@pytest.mark.parametrize("field,message", [
    ("translation", "camera 'left' has no 'translation'"),
    ("rotation", "camera 'left' has no 'rotation'"),
    ("size", "camera 'left' has no 'size' = [width, height]; add it to the file"),
    ("matrix", "no camera tables found"),
])
def test_missing_fields_are_named(tmp_path, field, message):
    p = write_toml_calibration(two_cameras(), tmp_path / "calibration.toml")
    lines = p.read_text().splitlines()
    first_table_end = lines.index("")  # drop the field from the first camera only (for 'matrix': from both)
    kept = [ln for i, ln in enumerate(lines)
            if not (ln.startswith(f"{field} =") and (field == "matrix" or i < first_table_end))]
    p.write_text("\n".join(kept))
    with pytest.raises(CalibrationError) as err:
        read_calibration(p)
    assert message in one_line(err)


def test_unknown_formats_are_named(tmp_path):
    (tmp_path / "calibration.json").write_text('{"cameras": []}')
    with pytest.raises(CalibrationError) as err:
        load_capture(tmp_path)
    assert "calibration.json is not a calibration format this reads; convert it to an anipose-style" in one_line(err)
    with pytest.raises(CalibrationError) as err:
        read_calibration(tmp_path / "calibration.json")
    assert one_line(err).startswith("calibration.json: unrecognised calibration format; convert it")
