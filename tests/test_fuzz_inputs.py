"""Fuzzing the calibration readers and the capture loader with generated inputs: whatever the file
holds, they load or raise the project's own error types (core/capture: CalibrationError, CaptureError,
FrameSourceError, each an InputError, the user's to fix), never a TypeError, KeyError, cv2.error or a crash.
Deterministic (derandomize) and bounded (max_examples), so CI runs the same inputs in a few seconds."""
import math
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from markerless_mocap.core.capture.calibration import CalibrationError, read_calibration  # noqa: E402
from markerless_mocap.core.capture.capture import CaptureError, load_capture  # noqa: E402
from markerless_mocap.core.capture.frames import FrameSourceError  # noqa: E402
from markerless_mocap.core.errors import InputError  # noqa: E402

OWN_ERRORS = (CalibrationError, CaptureError, FrameSourceError)
DATA = Path(__file__).parent / "data" / "calibration"
FUZZ = settings(max_examples=120, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])


def loads_or_refuses(read):
    """Call read(); the only acceptable failures are the project's own."""
    try:
        result = read()
    except OWN_ERRORS as exc:
        assert str(exc).strip(), "an error without a message"
        assert isinstance(exc, InputError), "the user's file, so the user's error (not reported as a bug)"
        return None
    return result


# ---- TOML: structured camera tables whose fields may be wrong in every way -------------------------
numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.integers(-10**6, 10**6))
junk = st.one_of(st.text(max_size=5), st.booleans(), numbers)
vectors = st.one_of(st.lists(numbers, max_size=10), st.lists(st.lists(numbers, max_size=4), max_size=4), junk)


def good_camera(i):
    return {"name": f"cam{i}", "size": [640, 480],
            "matrix": [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]],
            "distortions": [0.0] * 5, "rotation": [0.0, 0.0, 0.0], "translation": [float(i), 0.0, 3.0]}


@st.composite
def camera_tables(draw):
    cams = []
    for i in range(draw(st.integers(0, 3))):
        cam = good_camera(i)
        for key in draw(st.sets(st.sampled_from(sorted(cam) + ["fisheye", "image_size"]), max_size=3)):
            action = draw(st.sampled_from(["drop", "vector", "junk"]))
            if action == "drop":
                cam.pop(key, None)
            else:
                cam[key] = draw(vectors if action == "vector" else junk)
        cams.append(cam)
    meta = draw(st.one_of(st.just({}), st.fixed_dictionaries({"units": st.one_of(st.sampled_from(["m", "mm", "cm"]),
                                                                                    st.text(max_size=4), numbers)})))
    return cams, meta


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return '"' + "".join(c if c.isalnum() or c in " _-." else f"\\u{ord(c):04x}" for c in v) + '"'
    return "[" + ", ".join(toml_value(x) for x in v) + "]"


def toml_text(cams, meta):
    lines = []
    for i, cam in enumerate(cams):
        lines.append(f"[cam_{i}]")
        lines += [f"{k} = {toml_value(v)}" for k, v in cam.items()]
    if meta:
        lines.append("[metadata]")
        lines += [f"{k} = {toml_value(v)}" for k, v in meta.items()]
    return "\n".join(lines) + "\n"


@FUZZ
@given(camera_tables())
def test_toml_reader_loads_or_refuses(tables):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "calibration.toml"
        path.write_text(toml_text(*tables))
        cams = loads_or_refuses(lambda: read_calibration(path))
        if cams is not None:  # what it loads is usable: finite, positive sizes
            for c in cams:
                assert np.all(np.isfinite(c.K)) and np.all(np.isfinite(c.t)) and c.width > 0 and c.height > 0


# ---- text mutations of the real sample files of every format ------------------------------------
@st.composite
def mutated(draw, text):
    """The text with a few numbers replaced by generated tokens, maybe cut short."""
    spans = [m.span() for m in re.finditer(r"-?\d+(\.\d*)?(e-?\d+)?", text)]
    for start, end in sorted(draw(st.lists(st.sampled_from(spans), max_size=4, unique=True)), reverse=True):
        token = draw(st.sampled_from(["nan", "inf", "-1", "0", "1e308", "", "x", "[", "\"", "1e-300", "99999999999"]))
        text = text[:start] + token + text[end:]
    if draw(st.booleans()):
        text = text[:draw(st.integers(0, len(text)))]
    return text


SAMPLES = {name: (DATA / name).read_text() for name in ("anipose_mm.toml", "pose2sim_calib.toml", "qualisys.qca.txt",
                                                        "caliscope_camera_array.toml")}
EASYMOCAP = {name: (DATA / "easymocap" / name).read_text() for name in ("intri.yml", "extri.yml")}


@FUZZ
@given(st.sampled_from(sorted(SAMPLES)).flatmap(lambda name: st.tuples(st.just(name), mutated(SAMPLES[name]))))
def test_mutated_toml_and_qualisys_files_load_or_refuse(case):
    name, text = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_text(text)
        loads_or_refuses(lambda: read_calibration(path, units="mm" if name.startswith("anipose") else None))


@FUZZ
@given(st.sampled_from(sorted(EASYMOCAP)).flatmap(lambda name: st.tuples(st.just(name), mutated(EASYMOCAP[name]))))
def test_mutated_easymocap_files_load_or_refuse(case):
    name, text = case
    with tempfile.TemporaryDirectory() as d:
        for other, original in EASYMOCAP.items():
            (Path(d) / other).write_text(text if other == name else original)
        loads_or_refuses(lambda: read_calibration(Path(d)))


@FUZZ
@given(st.binary(max_size=300), st.sampled_from(["calibration.toml", "intri.yml", "x.qca.txt", "calib.json"]))
def test_arbitrary_bytes_load_or_refuse(data, name):
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / name).write_bytes(data)
        if name == "intri.yml":
            (Path(d) / "extri.yml").write_bytes(data)
        loads_or_refuses(lambda: read_calibration(Path(d)))


# ---- the capture loader: a calibration plus footage that may be missing, empty, broken or mismatched
W, H = 32, 24


def _png(value):
    import cv2

    ok, buf = cv2.imencode(".png", np.full((H, W, 3), value, np.uint8))
    return buf.tobytes()


footage_kinds = st.sampled_from(["video_bytes", "empty_file", "no_footage", "images", "empty_folder", "bad_image",
                                 "other_size_image", "wrong_name"])


@FUZZ
@given(st.lists(footage_kinds, min_size=2, max_size=3), st.binary(max_size=200), st.booleans(),
       st.sampled_from(["ok", "no_size", "text"]))
def test_capture_loader_loads_or_refuses(kinds, noise, with_plate, calibration):
    import cv2

    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        cams = [good_camera(i) for i in range(len(kinds))]
        for cam in cams:
            cam["size"] = [W, H]
            if calibration == "no_size":
                cam.pop("size")
        text = toml_text(cams, {}) if calibration != "text" else noise.decode("latin-1")
        (folder / "calibration.toml").write_text(text)
        videos = folder / "videos"
        videos.mkdir()
        for cam, kind in zip(cams, kinds):
            name = cam["name"]
            if kind == "video_bytes":
                (videos / f"{name}.mp4").write_bytes(noise)
            elif kind == "empty_file":
                (videos / f"{name}.mp4").write_bytes(b"")
            elif kind in ("images", "other_size_image", "bad_image", "empty_folder"):
                (videos / name).mkdir()
                if kind != "empty_folder":
                    (videos / name / "000001.png").write_bytes(_png(40))
                    second = {"images": _png(80), "bad_image": noise, "other_size_image": None}[kind]
                    if second is None:
                        ok, buf = cv2.imencode(".png", np.zeros((H + 2, W, 3), np.uint8))
                        second = buf.tobytes()
                    (videos / name / "000002.png").write_bytes(second)
            elif kind == "wrong_name":
                (videos / f"{name}_typo.mp4").write_bytes(noise)
        if with_plate:
            (folder / "background").mkdir()
            (folder / "background" / f"{cams[0]['name']}.png").write_bytes(noise or _png(10))
        capture = loads_or_refuses(lambda: load_capture(folder))
        if capture is not None:
            try:  # every frame it says it has can be read, or refused in the project's words
                for f in range(capture.frames.n_frames):
                    loads_or_refuses(lambda f=f: capture.frames.read(f))
            finally:
                capture.close()
