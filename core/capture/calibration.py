"""Multi-camera calibration files -> list[Camera] (metres, OpenCV convention), and writers.

Formats (details and sources: docs blender-and-calibration.md section 5):
* TOML family, one tolerant reader: anipose `calibration.toml`, FreeMoCap, Pose2Sim `Calib.toml`,
  Caliscope `camera_array.toml` (`[cameras.<id>]` nested tables). A camera is any table holding
  `matrix`; image size from `size` or `image_size` ([W, H]); `rotation` Rodrigues 3-vector or 3x3;
  4/5/8 distortion values; `fisheye = true` is refused.
* OpenCV FileStorage `intri.yml` + `extri.yml` (EasyMocap).
* Qualisys `.qca.txt` (XML), converted the way Pose2Sim's `calib_qca_fun` does (see _read_qca).

Units: everything returned is in metres. Source units come from the `units` argument, else the
file (`[metadata] units = "mm"`), else the format's convention (FreeMoCap and Qualisys: mm), else m.
"""
from __future__ import annotations

import math
import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import InputError
from .camera import Camera, CameraError, matrix_to_rodrigues, rodrigues_to_matrix, rotation_problem

UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_UNIT_ALIASES = {"m": "m", "meter": "m", "meters": "m", "metre": "m", "metres": "m",
                 "cm": "cm", "centimeter": "cm", "centimeters": "cm", "centimetre": "cm", "centimetres": "cm",
                 "mm": "mm", "millimeter": "mm", "millimeters": "mm", "millimetre": "mm", "millimetres": "mm"}
# No capture room has cameras further apart than this, or all closer together than that: a spread
# outside the two is a file in millimetres read as metres (x1000), or the other way round (/1000).
LARGEST_CAMERA_SPREAD_M = 100.0
SMALLEST_CAMERA_SPREAD_M = 0.02


class CalibrationError(InputError):
    """A calibration file cannot be used; the message names the file, the camera and the problem."""


class CalibrationNotFoundError(CalibrationError, FileNotFoundError):
    pass


class MissingImageSizeError(CalibrationError):
    """The file gives no image size for a camera; pass image_sizes (e.g. read from the videos)."""


def natural_key(name: str):
    """Sort key placing cam_2 before cam_10."""
    return [(0, int(part), "") if part.isdigit() else (1, 0, part.lower()) for part in re.split(r"(\d+)", str(name))]


def normalize_units(units, where: str) -> str:
    key = str(units).strip().lower()
    if key not in _UNIT_ALIASES:
        raise CalibrationError(f"{where}: unknown units {units!r}; use one of 'm', 'cm', 'mm'")
    return _UNIT_ALIASES[key]


# ---- dispatch -----------------------------------------------------------------------------------
def find_calibration_file(folder) -> Path:
    """The calibration file inside a capture folder (calibration.toml, intri.yml + extri.yml, *.qca.txt)."""
    folder = Path(folder)
    if (folder / "calibration.toml").is_file():
        return folder / "calibration.toml"
    if (folder / "intri.yml").is_file() or (folder / "extri.yml").is_file():
        return folder / "intri.yml"
    candidates = sorted(folder.glob("*.toml")) + sorted(folder.glob("*.qca.txt"))
    if len(candidates) == 1:
        return candidates[0]
    if len(candidates) > 1:
        names = ", ".join(p.name for p in candidates)
        raise CalibrationError(f"{folder}: several calibration files ({names}); keep one or name it calibration.toml")
    lookalikes = sorted(p.name for p in folder.glob("*calib*") if p.is_file())
    if lookalikes:
        raise CalibrationError(f"{folder}: {', '.join(lookalikes)} is not a calibration format this reads; convert it "
                               "to an anipose-style calibration.toml (or EasyMocap intri.yml + extri.yml, or a "
                               "Qualisys .qca.txt)")
    raise CalibrationNotFoundError(
        f"{folder}: no calibration found; expected calibration.toml, intri.yml + extri.yml, or a *.qca.txt file")


def read_calibration(path, units: str | None = None, image_sizes: dict | None = None) -> list[Camera]:
    """Read a calibration file (or a folder holding one) into cameras in metres, sorted naturally by name.

    units: the file's length unit ('m', 'cm', 'mm'), overriding what the file says.
    image_sizes: {camera name: (W, H)} for formats that may omit the size (EasyMocap H_/W_).
    """
    path = Path(path)
    if path.is_dir():
        path = find_calibration_file(path)
    name = path.name.lower()
    if name in ("intri.yml", "extri.yml", "intri.yaml", "extri.yaml") or path.suffix.lower() in (".yml", ".yaml"):
        cams = _read_easymocap(path, units, image_sizes)
    elif not path.is_file():
        raise CalibrationNotFoundError(f"{path}: calibration file not found")
    elif name.endswith(".qca.txt") or name.endswith(".qca") or _sniff(path) == "xml":
        cams = _read_qca(path, units)
    elif path.suffix.lower() in (".toml", "") or (path.suffix.lower() in (".txt", ".cfg") and _sniff(path) == "toml"):
        cams = _read_toml(path, units, image_sizes)
    else:
        raise CalibrationError(f"{path.name}: unrecognised calibration format; convert it to an anipose-style "
                               "calibration.toml (or EasyMocap intri.yml + extri.yml, or a Qualisys .qca.txt)")
    seen = set()
    for c in cams:
        if c.name in seen:
            raise CalibrationError(f"{path.name}: two cameras are named '{c.name}'; camera names must be unique")
        seen.add(c.name)
    cams.sort(key=lambda c: natural_key(c.name))
    _require_plausible_units(path, cams)
    return cams


def require_two_cameras(path, cams: list[Camera]) -> None:
    """A capture is tracked from two views at least (the readers themselves also read a single camera)."""
    if len(cams) < 2:
        found = f"one camera ('{cams[0].name}')" if cams else "no camera"
        raise CalibrationError(f"{Path(path).name}: {found} found; multi-camera tracking needs at least two "
                               "calibrated cameras: calibrate every camera of the take into one file")


def _sniff(path: Path) -> str:
    head = path.read_bytes()[:200].decode("utf-8", "replace").lstrip()
    if head.startswith("<"):
        return "xml"
    if head.startswith("%YAML"):
        return "yaml"
    return "toml"


def _units_fix(path: Path, unit: str) -> str:
    if path.suffix.lower() == ".toml":
        return f'add units = "{unit}" under [metadata] in the file (or choose Units: {unit} when importing)'
    return f"choose Units: {unit} when importing (load_capture(..., units='{unit}'))"


def _require_plausible_units(path: Path, cams: list[Camera]) -> None:
    """Camera centres thousands of metres apart, or all within millimetres, mean the length unit is wrong."""
    if len(cams) < 2:
        return
    centres = np.array([c.center for c in cams])
    spread = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=-1)))
    if spread > LARGEST_CAMERA_SPREAD_M:
        raise CalibrationError(f"{path.name}: the cameras are up to {spread:.0f} m apart, more than any capture room; "
                               f"the file is probably in millimetres read as metres: {_units_fix(path, 'mm')}")
    if spread < SMALLEST_CAMERA_SPREAD_M:
        raise CalibrationError(f"{path.name}: the cameras are all within {spread * 1000:.1f} mm of each other; the "
                               f"file is probably in metres read as millimetres: {_units_fix(path, 'm')}")


_NOT_FINITE_FIX = "the calibration did not converge or the file was edited: recalibrate, or correct the value"


def _make_camera(where: str, name, K, dist, R, t, width, height) -> Camera:
    for what, value in (("intrinsic matrix", K), ("distortion", dist), ("rotation", R), ("translation", t)):
        if not np.all(np.isfinite(np.asarray(value, dtype=np.float64))):
            raise CalibrationError(f"{where}: camera '{name}' has NaN or infinite values in its {what}; "
                                   f"{_NOT_FINITE_FIX}")
    try:
        return Camera(str(name), K, dist, R, t, width, height)
    except CameraError as exc:
        raise CalibrationError(f"{where}: {exc}") from None


def _as_size(where: str, cam: str, value) -> tuple[int, int]:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.size != 2 or not np.all(np.isfinite(arr)) or np.any(arr <= 0) or np.any(arr != np.round(arr)):
        raise CalibrationError(f"{where}: camera '{cam}' has image size {value!r}; expected two positive whole "
                               "numbers [width, height]")
    return int(arr[0]), int(arr[1])


def _image_size(where: str, cam: str, in_file, image_sizes, missing_message: str) -> tuple[int, int]:
    """The size the file gives, else the one measured from the footage, else a MissingImageSizeError."""
    if in_file is None:
        if not (image_sizes and cam in image_sizes):
            raise MissingImageSizeError(f"{where}: camera '{cam}' {missing_message}")
        in_file = image_sizes[cam]
    return _as_size(where, cam, in_file)


# ---- TOML family --------------------------------------------------------------------------------
def _camera_tables(doc: dict, prefix: str = ""):
    """(key, table) for every table holding a 'matrix', searching nested tables (Caliscope)."""
    for key, value in doc.items():
        if not isinstance(value, dict) or key == "metadata":
            continue
        if "matrix" in value:
            yield key, value
        else:
            yield from _camera_tables(value, prefix + key + ".")


def _numeric(where: str, cam: str, key: str, value, shapes: tuple) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: camera '{cam}' has a non-numeric or ragged '{key}': {value!r}") from None
    if arr.shape not in shapes:
        counts = [str(sh[0]) for sh in shapes if len(sh) == 1]
        wants = ([(", ".join(counts[:-1]) + " or " if len(counts) > 1 else "") + counts[-1] + " values"]
                 if counts else [])
        wants += ["x".join(str(s) for s in sh) for sh in shapes if len(sh) > 1]
        want = " or ".join(wants)
        if arr.ndim == 1:
            got = f"{arr.size} values in '{key}'"
        else:
            got = f"a {'x'.join(str(s) for s in arr.shape) or 'single number'} '{key}'"
        raise CalibrationError(f"{where}: camera '{cam}' has {got}; expected {want}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{where}: camera '{cam}' has NaN or infinite values in '{key}'; {_NOT_FINITE_FIX}")
    return arr


def _toml_units(where: str, doc: dict, units) -> str:
    if units is not None:
        return normalize_units(units, where)
    meta = doc.get("metadata", {})
    if isinstance(meta, dict) and "units" in meta:
        return normalize_units(meta["units"], where)
    # FreeMoCap stores camera positions in millimetres and says so only through its board description.
    board = meta.get("board", {}) if isinstance(meta, dict) else {}
    looks_freemocap = isinstance(board, dict) and "square_length_mm" in board
    looks_freemocap |= any("world_position" in t for _, t in _camera_tables(doc))
    return "mm" if looks_freemocap else "m"


def _read_toml(path: Path, units, image_sizes) -> list[Camera]:
    where = path.name
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise CalibrationError(f"{where}: not a text file (not UTF-8); export the calibration as TOML text") from None
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{where}: not valid TOML ({exc})") from None
    unit = _toml_units(where, doc, units)
    scale = UNIT_SCALE[unit]
    cams = []
    for key, table in _camera_tables(doc):
        name = str(table.get("name", key))
        if table.get("fisheye", False):
            raise CalibrationError(f"{where}: camera '{name}' is a fisheye camera; fisheye lenses are not supported "
                                   "(calibrate with the standard pinhole + distortion model)")
        K = _numeric(where, name, "matrix", table["matrix"], ((3, 3),))
        dist = _numeric(where, name, "distortions", table.get("distortions", []), ((0,), (4,), (5,), (8,)))
        for key_name in ("rotation", "translation"):
            if key_name not in table:
                raise CalibrationError(f"{where}: camera '{name}' has no '{key_name}'")
        rot = _numeric(where, name, "rotation", table["rotation"], ((3,), (3, 3)))
        if rot.shape == (3, 3):
            problem = rotation_problem(rot, tol=1e-5)
            if problem:
                raise CalibrationError(f"{where}: camera '{name}' 'rotation' {problem}")
            R = _nearest_rotation(rot)
        else:
            R = rodrigues_to_matrix(rot)
        t = _numeric(where, name, "translation", table["translation"], ((3,),)) * scale
        W, H = _image_size(where, name, table.get("size", table.get("image_size")), image_sizes,
                           "has no 'size' = [width, height]; add it to the file")
        cams.append(_make_camera(where, name, K, dist, R, t, W, H))
    if not cams:
        raise CalibrationError(f"{where}: no camera tables found (a camera is a table with 'matrix', 'size', "
                               "'distortions', 'rotation', 'translation')")
    return cams


def _nearest_rotation(R: np.ndarray) -> np.ndarray:
    """Snap a slightly non-orthonormal matrix (rounded in the file) to the nearest rotation."""
    u, _, vt = np.linalg.svd(R)
    return u @ vt


# ---- EasyMocap / OpenCV FileStorage ----------------------------------------------------------------
def _easymocap_paths(path: Path) -> tuple[Path, Path]:
    folder = path if path.is_dir() else path.parent
    ext = path.suffix if path.suffix.lower() in (".yml", ".yaml") else ".yml"
    intri, extri = folder / f"intri{ext}", folder / f"extri{ext}"
    for p in (intri, extri):
        if not p.is_file():
            raise CalibrationNotFoundError(f"{p}: not found; EasyMocap calibration needs both intri{ext} and "
                                           f"extri{ext} in {folder}")
    return intri, extri


def _open_storage(path: Path):
    import cv2

    if path.stat().st_size == 0:
        raise CalibrationError(f"{path.name}: the file is empty; export the calibration again")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # some parse errors surface as SystemError from the binding
        raise CalibrationError(f"{path.name}: not a readable OpenCV YAML file ({str(exc).strip()})") from None
    if not fs.isOpened():
        raise CalibrationError(f"{path.name}: OpenCV could not open it as a YAML/XML FileStorage file")
    return fs


def _storage_names(fs, where: str) -> list[str]:
    node = fs.getNode("names")
    if node.empty() or not node.isSeq():
        raise CalibrationError(f"{where}: no 'names' list; EasyMocap files start with names: [\"01\", \"02\", ...]")
    names = []
    for i in range(node.size()):
        item = node.at(i)
        if item.isString():
            names.append(item.string())
        elif item.isInt() or (item.isReal() and float(item.real()).is_integer()):
            names.append(str(int(item.real())))
        else:
            raise CalibrationError(f"{where}: entry {i} of 'names' is not a camera name; write names as strings")
    return names


def _storage_mat(fs, where: str, cam: str, key: str, required: bool = True):
    node = fs.getNode(key)
    if node.empty():
        if required:
            raise CalibrationError(f"{where}: camera '{cam}' has no '{key}' entry")
        return None
    import cv2

    try:
        mat = node.mat()
    except (cv2.error, SystemError):  # rows x cols disagree with the data, or an unknown element type
        mat = None
    if mat is None:
        raise CalibrationError(f"{where}: camera '{cam}' entry '{key}' is not an !!opencv-matrix")
    return np.asarray(mat, dtype=np.float64)


def _read_easymocap(path: Path, units, image_sizes) -> list[Camera]:
    import cv2

    try:
        return _read_easymocap_files(path, units, image_sizes)
    except (cv2.error, SystemError) as exc:  # OpenCV asserts on structures it did not expect (a list for a map...)
        reason = " ".join(str(exc).split())[-160:]
        raise CalibrationError(f"{path.name}: OpenCV cannot read this EasyMocap file's structure ({reason}); export "
                               "intri.yml and extri.yml again") from None


def _read_easymocap_files(path: Path, units, image_sizes) -> list[Camera]:
    intri_path, extri_path = _easymocap_paths(path)
    wi, we = intri_path.name, extri_path.name
    scale = UNIT_SCALE[normalize_units(units, wi)] if units is not None else 1.0
    fi, fe = _open_storage(intri_path), _open_storage(extri_path)
    try:
        names = _storage_names(fi, wi)
        missing = [n for n in names if n not in _storage_names(fe, we)]
        if missing:
            raise CalibrationError(f"{we}: cameras {missing} listed in {wi} have no extrinsics")
        cams = []
        for name in names:
            K = _storage_mat(fi, wi, name, f"K_{name}")
            if K.shape != (3, 3):
                raise CalibrationError(f"{wi}: camera '{name}' has a {K.shape[0]}x{K.shape[1]} 'K_{name}'; "
                                       "expected 3x3")
            dist = _storage_mat(fi, wi, name, f"dist_{name}", required=False)
            dist = np.zeros(0) if dist is None else dist.reshape(-1)
            if dist.size not in (0, 4, 5, 8):
                raise CalibrationError(f"{wi}: camera '{name}' has {dist.size} values in 'dist_{name}'; "
                                       "expected 4, 5 or 8")
            H_node, W_node = fi.getNode(f"H_{name}"), fi.getNode(f"W_{name}")
            in_file = (W_node.real(), H_node.real()) if not H_node.empty() and not W_node.empty() else None
            W, H = _image_size(wi, name, in_file, image_sizes,
                               f"has no H_{name}/W_{name} image size; add them to intri.yml or load it with its "
                               "videos so the size can be read from them")
            R = _easymocap_rotation(fe, we, name)
            T = _storage_mat(fe, we, name, f"T_{name}")
            if T.size != 3:
                raise CalibrationError(f"{we}: camera '{name}' 'T_{name}' has {T.size} values; expected 3")
            cams.append(_make_camera(f"{wi}/{we}", name, K, dist, R, T.reshape(3) * scale, W, H))
    finally:
        fi.release()
        fe.release()
    return cams


def _easymocap_rotation(fe, where: str, name: str) -> np.ndarray:
    rvec = _storage_mat(fe, where, name, f"R_{name}", required=False)
    rot = _storage_mat(fe, where, name, f"Rot_{name}", required=False)
    if rvec is None and rot is None:
        raise CalibrationError(f"{where}: camera '{name}' has neither 'R_{name}' (Rodrigues) nor 'Rot_{name}' (3x3)")
    if rot is not None:
        if rot.shape != (3, 3):
            raise CalibrationError(f"{where}: camera '{name}' has a {rot.shape[0]}x{rot.shape[1]} 'Rot_{name}'; "
                                   "expected 3x3")
        problem = rotation_problem(rot, tol=1e-5)
        if problem:
            raise CalibrationError(f"{where}: camera '{name}' 'Rot_{name}' {problem}")
    if rvec is not None:
        if rvec.size != 3:
            raise CalibrationError(f"{where}: camera '{name}' 'R_{name}' has {rvec.size} values; expected a 3x1 "
                                   "Rodrigues vector (a 3x3 matrix belongs in 'Rot_{name}')")
        R = rodrigues_to_matrix(rvec)
        if rot is not None and np.abs(R - rot).max() > 1e-4:
            raise CalibrationError(f"{where}: camera '{name}' 'R_{name}' and 'Rot_{name}' disagree "
                                   f"(max difference {np.abs(R - rot).max():.3g}); remove the wrong one")
        return R
    return _nearest_rotation(rot)


# ---- Qualisys .qca.txt ------------------------------------------------------------------------------
_QCA_SUBPIXEL = 64.0  # QTM stores focal length and principal point in 1/64 pixel units


def _read_qca(path: Path, units) -> list[Camera]:
    """Qualisys QTM calibration export (.qca.txt, XML), following Pose2Sim's calib_qca_fun.

    Verified against Pose2Sim/calibration.py (read_qca, world_to_camera_persp, rotate_cam):
    * image size = fov_video (right - left + 1, bottom - top + 1);
    * fx, fy, cx, cy = focalLengthU/V, centerPointU/V divided by 64, minus fov_video left/top for c;
    * <transform x y z> is the camera position in mm; the matrix R_q with R_q[i, j] = r_(j+1)(i+1)
      is camera -> world with the QTM camera looking down its -z axis (+y up), so the OpenCV
      world -> camera rotation is F R_q^T with F = diag(1, -1, -1) and t = -R C;
    * only video cameras (model containing 'Video', or 'none') are kept when any is present.
    Not taken from Pose2Sim: it also divides the distortion coefficients by 64; they act on
    normalised coordinates (pixel / focal), which the 1/64 units cancel out of, so they are used
    as stored (k1 k2 p1 p2 k3 from radialDistortion1/2, tangentalDistortion1/2, radialDistortion3).
    Whether QTM's lens model equals OpenCV's for these coefficients is not verified.
    """
    where = path.name
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise CalibrationError(f"{where}: not valid XML ({exc})") from None
    scale = UNIT_SCALE[normalize_units(units, where)] if units is not None else UNIT_SCALE["mm"]
    elems = root.findall(".//cameras/camera") or root.findall(".//camera")
    if not elems:
        raise CalibrationError(f"{where}: no <camera> elements; is this a Qualisys .qca.txt export?")
    video = [e for e in elems if "video" in e.get("model", "").lower() or e.get("model", "") == "none"]
    cams = []
    for elem in (video or elems):
        name = elem.get("serial") or f"cam_{len(cams)}"
        rotation = elem.get("viewrotation", "0")
        if rotation not in ("0", "", None):
            raise CalibrationError(f"{where}: camera '{name}' has viewrotation={rotation}; rotated (portrait) "
                                   "camera views are not supported: export the calibration unrotated")
        fov, tr, intr = elem.find("fov_video"), elem.find("transform"), elem.find("intrinsic")
        for tag, node in (("fov_video", fov), ("transform", tr), ("intrinsic", intr)):
            if node is None:
                raise CalibrationError(f"{where}: camera '{name}' has no <{tag}> element")

        def num(node, attr, default=None, name=name):
            value = node.get(attr)
            if value is None:
                if default is not None:
                    return default
                raise CalibrationError(f"{where}: camera '{name}' <{node.tag}> lacks the '{attr}' attribute")
            try:
                return float(value)
            except ValueError:
                raise CalibrationError(f"{where}: camera '{name}' <{node.tag} {attr}=\"{value}\"> "
                                       "is not a number") from None

        left, top = num(fov, "left"), num(fov, "top")
        W, H = num(fov, "right") - left + 1, num(fov, "bottom") - top + 1
        fx, fy = num(intr, "focalLengthU") / _QCA_SUBPIXEL, num(intr, "focalLengthV") / _QCA_SUBPIXEL
        cx = num(intr, "centerPointU") / _QCA_SUBPIXEL - left
        cy = num(intr, "centerPointV") / _QCA_SUBPIXEL - top
        skew = num(intr, "skew", 0.0) / _QCA_SUBPIXEL
        dist = [num(intr, "radialDistortion1", 0.0), num(intr, "radialDistortion2", 0.0),
                num(intr, "tangentalDistortion1", 0.0), num(intr, "tangentalDistortion2", 0.0),
                num(intr, "radialDistortion3", 0.0)]
        r = np.array([[num(tr, f"r{i}{j}") for j in (1, 2, 3)] for i in (1, 2, 3)])
        problem = rotation_problem(r, tol=1e-4)
        if problem:
            raise CalibrationError(f"{where}: camera '{name}' <transform> rotation r11..r33 {problem}")
        r = _nearest_rotation(r)
        C = np.array([num(tr, "x"), num(tr, "y"), num(tr, "z")]) * scale
        R = np.diag([1.0, -1.0, -1.0]) @ r
        K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        cams.append(_make_camera(where, name, K, dist, R, -R @ C, *_as_size(where, name, (W, H))))
    return cams


# ---- writers ------------------------------------------------------------------------------------
def _toml_str(s: str) -> str:
    out = ['"']
    for ch in str(s):
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _toml_float(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise CalibrationError(f"cannot write the non-finite value {x} to TOML")
    return repr(x)  # shortest string that reads back to the same double


def _toml_list(values) -> str:
    return "[" + ", ".join(_toml_float(v) for v in values) + "]"


def write_toml_calibration(cameras, path, units: str = "m") -> Path:
    """Write anipose / Pose2Sim style TOML: [cam_<i>] tables, Rodrigues rotation, size [W, H]."""
    path = Path(path)
    unit = normalize_units(units, path.name)
    scale = UNIT_SCALE[unit]
    lines = []
    for i, cam in enumerate(cameras):
        lines += [f"[cam_{i}]",
                  f"name = {_toml_str(cam.name)}",
                  f"size = [{int(cam.width)}, {int(cam.height)}]",
                  "matrix = [" + ", ".join(_toml_list(row) for row in cam.K) + "]",
                  f"distortions = {_toml_list(cam.dist)}",
                  f"rotation = {_toml_list(matrix_to_rodrigues(cam.R))}",
                  f"translation = {_toml_list(np.asarray(cam.t) / scale)}",
                  "fisheye = false",
                  ""]
    lines += ["[metadata]", f"units = {_toml_str(unit)}", "adjusted = false", "error = 0.0", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def write_easymocap_calibration(cameras, folder) -> tuple[Path, Path]:
    """Write EasyMocap intri.yml + extri.yml (metres) with H_/W_ image sizes."""
    import cv2

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    intri, extri = folder / "intri.yml", folder / "extri.yml"
    for file_path, kind in ((intri, "intri"), (extri, "extri")):
        fs = cv2.FileStorage(str(file_path), cv2.FILE_STORAGE_WRITE)
        fs.startWriteStruct("names", cv2.FileNode_SEQ)
        for cam in cameras:
            fs.write("", str(cam.name))
        fs.endWriteStruct()
        for cam in cameras:
            n = cam.name
            if kind == "intri":
                fs.write(f"K_{n}", np.asarray(cam.K, dtype=np.float64))
                d = np.asarray(cam.dist, dtype=np.float64).reshape(1, -1)
                fs.write(f"dist_{n}", d if d.size else np.zeros((1, 5)))
                fs.write(f"H_{n}", int(cam.height))
                fs.write(f"W_{n}", int(cam.width))
            else:
                fs.write(f"R_{n}", matrix_to_rodrigues(cam.R).reshape(3, 1))
                fs.write(f"Rot_{n}", np.asarray(cam.R, dtype=np.float64))
                fs.write(f"T_{n}", np.asarray(cam.t, dtype=np.float64).reshape(3, 1))
        fs.release()
    return intri, extri
