"""3D error against ground truth: 15 joints matched by bone name, per-frame error, PCK, plots.

The joint set follows HumanEva's 15 markers as far as bone heads express them (algorithms.md 8.1):
pelvis, hips, knees, ankles, shoulders, elbows, wrists, neck, head. EVAL_JOINTS is the one place
that says which bone's head stands for which joint, per rig naming.
"""
import json
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from .results import load_joints

# joint -> candidate bone names (first one present wins); the joint is the bone's head.
EVAL_JOINTS = {
    "pelvis": ("Hips", "mixamorig:Hips", "DEF-spine"),
    "l_hip": ("LeftUpLeg", "mixamorig:LeftUpLeg", "DEF-thigh.L"),
    "r_hip": ("RightUpLeg", "mixamorig:RightUpLeg", "DEF-thigh.R"),
    "l_knee": ("LeftLeg", "mixamorig:LeftLeg", "DEF-shin.L"),
    "r_knee": ("RightLeg", "mixamorig:RightLeg", "DEF-shin.R"),
    "l_ankle": ("LeftFoot", "mixamorig:LeftFoot", "DEF-foot.L"),
    "r_ankle": ("RightFoot", "mixamorig:RightFoot", "DEF-foot.R"),
    "l_shoulder": ("LeftArm", "mixamorig:LeftArm", "DEF-upper_arm.L"),
    "r_shoulder": ("RightArm", "mixamorig:RightArm", "DEF-upper_arm.R"),
    "l_elbow": ("LeftForeArm", "mixamorig:LeftForeArm", "DEF-forearm.L"),
    "r_elbow": ("RightForeArm", "mixamorig:RightForeArm", "DEF-forearm.R"),
    "l_wrist": ("LeftHand", "mixamorig:LeftHand", "DEF-hand.L"),
    "r_wrist": ("RightHand", "mixamorig:RightHand", "DEF-hand.R"),
    "neck": ("Neck", "mixamorig:Neck", "DEF-spine.004"),
    "head": ("Head", "mixamorig:Head", "DEF-spine.006"),
}


class EvaluationError(ValueError):
    pass


def joint_indices(names, what):
    idx, missing = [], []
    for joint, candidates in EVAL_JOINTS.items():
        hit = next((names.index(c) for c in candidates if c in names), None)
        (missing if hit is None else idx).append(joint if hit is None else hit)
    if missing:
        raise EvaluationError(f"{what}: no bone for joints {', '.join(missing)}; "
                              f"core/evaluation.py EVAL_JOINTS lists the bone names it looks for")
    return np.array(idx)


@dataclass
class ErrorSummary:
    frames: int
    mean_mm: float
    std_mm: float
    median_mm: float
    max_mm: float
    pck50: float
    pck100: float
    per_joint_mm: dict

    def json_line(self, **extra):
        return json.dumps({**asdict(self), **extra})


def joint_errors(result_path, truth_path):
    """(frames (F,), errors (F,15) in metres) on the frames both files have."""
    r_names, r_frames, r_pos = load_joints(result_path)
    t_names, t_frames, t_pos = load_joints(truth_path)
    ri, ti = joint_indices(r_names, str(result_path)), joint_indices(t_names, str(truth_path))
    common, r_at, t_at = np.intersect1d(r_frames, t_frames, return_indices=True)
    if len(common) == 0:
        raise EvaluationError(f"{result_path} (frames {r_frames.min()}-{r_frames.max()}) and {truth_path} "
                              f"(frames {t_frames.min()}-{t_frames.max()}) share no frame")
    err = np.linalg.norm(r_pos[r_at][:, ri] - t_pos[t_at][:, ti], axis=-1)
    return common, err


def summarise(frames, errors):
    per_frame = errors.mean(axis=1) * 1000
    return ErrorSummary(
        frames=int(len(frames)), mean_mm=float(per_frame.mean()), std_mm=float(per_frame.std()),
        median_mm=float(np.median(per_frame)), max_mm=float(errors.max() * 1000),
        pck50=float((errors < 0.05).mean()), pck100=float((errors < 0.10).mean()),
        per_joint_mm={j: float(e) for j, e in zip(EVAL_JOINTS, errors.mean(axis=0) * 1000)})


def plot_per_frame(frames, errors, path, title="mean 3D joint error per frame"):
    """A small line plot (OpenCV, no plotting library needed)."""
    per_frame = errors.mean(axis=1) * 1000
    W, H, m = 800, 360, 50
    img = np.full((H, W, 3), 255, np.uint8)
    top = max(50.0, float(np.ceil(per_frame.max() / 25) * 25))
    x = m + (frames - frames.min()) / max(1, frames.max() - frames.min()) * (W - 2 * m)
    y = H - m - per_frame / top * (H - 2 * m)
    for v in np.arange(0, top + 1, 25):
        yy = int(H - m - v / top * (H - 2 * m))
        cv2.line(img, (m, yy), (W - m, yy), (225, 225, 225), 1)
        cv2.putText(img, f"{v:.0f}", (5, yy + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (80, 80, 80), 1)
    cv2.polylines(img, [np.stack([x, y], 1).astype(np.int32)], False, (200, 80, 20), 2, cv2.LINE_AA)
    cv2.putText(img, f"{title} (mm); mean {per_frame.mean():.1f}", (m, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"frames {frames.min()}-{frames.max()}", (W // 2 - 50, H - 15), cv2.FONT_HERSHEY_SIMPLEX,
                0.45, (0, 0, 0), 1)
    cv2.imwrite(str(path), img)
    return path
