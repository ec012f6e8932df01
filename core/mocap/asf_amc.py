"""Acclaim ASF (skeleton) + AMC (motion) reader -> MotionClip.

ASF facts used (Acclaim spec, as written by the CMU/VICON tools):
* every bone has a `direction` (unit, world axes of the rest pose) and a `length`; a child starts
  where its parent ends, so the child's offset is parent.direction * parent.length;
* `axis ax ay az XYZ` gives the bone's local frame C as rotations about fixed axes applied in the
  listed order, so XYZ -> C = Rz @ Ry @ Rx (degrees unless `:units angle rad`); AMC `dof rx ry rz`
  values compose the same way. (Checked: with this order the CMU AMC reproduces the CMU BVH of
  the same trial to 0.01 mm; the opposite order is centimetres off at the feet.)
* AMC values are the `dof` rotations in the listed order, in the bone's frame C, so the bone's
  rotation relative to rest in world axes is C @ M @ C^T; the root takes `order` (TX TY TZ RX RY RZ)
  and `axis` from the :root section;
* `:units length 0.45` means 1 unit = 1/0.45 inch (CMU).
"""
from pathlib import Path

import numpy as np

from .clip import MotionClip, MotionFileError, euler_matrix

INCH_M = 0.0254


def _fixed_axes_matrix(axes, angles):
    """Rotations about fixed (world) axes applied in the listed order: "XYZ" -> Rz @ Ry @ Rx."""
    return euler_matrix(axes[::-1], np.asarray(angles, dtype=np.float64)[..., ::-1])


def _sections(text):
    """Split an ASF into {':keyword': [lines]}."""
    out, key = {}, None
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith(":"):
            parts = line.split(None, 1)
            key = parts[0].lower()
            out.setdefault(key, [])
            if len(parts) > 1:
                out[key].append(parts[1])
        elif key is not None:
            out[key].append(line)
    return out


def _read_asf(path):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ASF file not found: {path}")
    sec = _sections(path.read_text(errors="replace"))
    for need in (":bonedata", ":hierarchy", ":root"):
        if need not in sec:
            raise MotionFileError(f"{path}: no '{need}' section; is this an Acclaim ASF skeleton file?")
    length_unit, angle_deg = 1.0, True
    for line in sec.get(":units", []):
        k, *v = line.split()
        if k == "length":
            length_unit = float(v[0])
        elif k == "angle":
            angle_deg = v[0].lower().startswith("deg")
    root = {"order": ["TX", "TY", "TZ", "RX", "RY", "RZ"], "axis": "XYZ", "position": np.zeros(3),
            "orientation": np.zeros(3)}
    for line in sec[":root"]:
        k, *v = line.split()
        k = k.lower()
        if k == "order":
            root["order"] = [s.upper() for s in v]
        elif k == "axis":
            root["axis"] = v[0].upper()
        elif k in ("position", "orientation"):
            root[k] = np.array([float(x) for x in v])
    bones, cur = {}, None
    for line in sec[":bonedata"]:
        k, *v = line.split()
        k = k.lower()
        if k == "begin":
            cur = {"dof": [], "axis": np.zeros(3), "axis_order": "XYZ"}
        elif k == "end":
            if cur is None or "name" not in cur:
                raise MotionFileError(f"{path}: a bone block without a name")
            bones[cur["name"]] = cur
            cur = None
        elif cur is None:
            continue
        elif k == "name":
            cur["name"] = v[0]
        elif k == "direction":
            cur["direction"] = np.array([float(x) for x in v[:3]])
        elif k == "length":
            cur["length"] = float(v[0])
        elif k == "axis":
            cur["axis"] = np.array([float(x) for x in v[:3]])
            cur["axis_order"] = v[3].upper() if len(v) > 3 else "XYZ"
        elif k == "dof":
            cur["dof"] = [s.lower() for s in v]
    children = {}
    for line in sec[":hierarchy"]:
        parts = line.split()
        if parts[0].lower() in ("begin", "end"):
            continue
        children.setdefault(parts[0], []).extend(parts[1:])
    return root, bones, children, length_unit, angle_deg


def _read_amc(path, names):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"AMC file not found: {path}")
    frames, cur = [], None
    for raw in path.read_text(errors="replace").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line or line.startswith(":"):
            continue
        parts = line.split()
        if len(parts) == 1 and parts[0].isdigit():
            cur = {}
            frames.append(cur)
            continue
        if cur is None:
            raise MotionFileError(f"{path}: motion data before the first frame number; is this an AMC file?")
        if parts[0] not in names:
            raise MotionFileError(f"{path}: bone '{parts[0]}' is not in the ASF skeleton; "
                                  "are the ASF and AMC files from the same subject?")
        cur[parts[0]] = np.array([float(x) for x in parts[1:]])
    if not frames:
        raise MotionFileError(f"{path}: no frames found")
    return frames


def read_asf_amc(asf_path, amc_path, fps=120.0):
    """Read an ASF skeleton and an AMC motion (AMC stores no rate: CMU captured at 120 fps)."""
    root, bones, children, length_unit, angle_deg = _read_asf(asf_path)
    # order joints parents first, walking the hierarchy from the root
    names, parents = ["root"], [-1]
    queue = [("root", 0)]
    while queue:
        name, idx = queue.pop(0)
        for child in children.get(name, []):
            if child not in bones:
                raise MotionFileError(f"{asf_path}: hierarchy names bone '{child}' that has no :bonedata entry")
            names.append(child)
            parents.append(idx)
            queue.append((child, len(names) - 1))
    J = len(names)
    scale = 1.0 if angle_deg else np.rad2deg(1.0)
    offsets = np.zeros((J, 3))
    rest = np.empty((J, 3, 3))
    rest[0] = _fixed_axes_matrix(root["axis"], root["orientation"] * scale)
    offsets[0] = root["position"]
    end_sites = {}
    for j in range(1, J):
        b = bones[names[j]]
        rest[j] = _fixed_axes_matrix(b["axis_order"], b["axis"] * scale)
        p = parents[j]
        if p > 0:
            pb = bones[names[p]]
            offsets[j] = pb["direction"] * pb["length"]
        if names[j] not in children:
            end_sites[j] = b["direction"] * b["length"]

    frames = _read_amc(amc_path, set(names))
    F = len(frames)
    local = np.tile(np.eye(3), (F, J, 1, 1))
    root_pos = np.zeros((F, 3))
    rot_order = "".join(o[1] for o in root["order"] if o.startswith("R"))
    for f, fr in enumerate(frames):
        if "root" not in fr:
            raise MotionFileError(f"{amc_path}: frame {f + 1} has no 'root' line")
        vals = dict(zip(root["order"], fr["root"]))
        root_pos[f] = [vals.get("TX", 0.0), vals.get("TY", 0.0), vals.get("TZ", 0.0)]
        local[f, 0] = _fixed_axes_matrix(rot_order, [vals.get("R" + a, 0.0) * scale for a in rot_order])
    # vectorise per bone over frames
    for j in range(1, J):
        dof = bones[names[j]]["dof"]
        axes = "".join(d[1].upper() for d in dof if d.startswith("r"))
        if not axes:
            continue
        vals = np.zeros((F, len(dof)))
        for f, fr in enumerate(frames):
            v = fr.get(names[j])
            if v is not None:
                vals[f, :len(v)] = v[:len(dof)]
        rcols = [k for k, d in enumerate(dof) if d.startswith("r")]
        local[:, j] = _fixed_axes_matrix(axes, vals[:, rcols] * scale)
    return MotionClip(names, np.array(parents), offsets, rest, local, root_pos, float(fps),
                      INCH_M / length_unit, end_sites)
