"""3D error against ground truth: 15 joints matched by bone name, per-frame error, PCK, plots.

The joint set follows HumanEva's 15 markers as far as bone heads express them (algorithms.md 8.1):
pelvis, hips, knees, ankles, shoulders, elbows, wrists, neck, head. EVAL_JOINTS is the one place
that says which bone's head stands for which joint, per rig naming.
"""
import json
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from ..errors import InputError
from .result_folder import load_joints

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


class EvaluationError(InputError):
    pass


def joint_indices(names, what):
    idx, missing = [], []
    for joint, candidates in EVAL_JOINTS.items():
        hit = next((names.index(c) for c in candidates if c in names), None)
        (missing if hit is None else idx).append(joint if hit is None else hit)
    if missing:
        raise EvaluationError(f"{what}: no bone for joints {', '.join(missing)}; "
                              f"core/results/evaluation.py EVAL_JOINTS lists the bone names it looks for")
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


# The keypoint-triangulation baseline (what FreeMoCap and Pose2Sim do): joints -> BlazePose landmark.
TRIANGULATION_JOINTS = {"l_shoulder": 11, "r_shoulder": 12, "l_elbow": 13, "r_elbow": 14, "l_wrist": 15,
                        "r_wrist": 16, "l_hip": 23, "r_hip": 24, "l_knee": 25, "r_knee": 26, "l_ankle": 27,
                        "r_ankle": 28}


def triangulation_errors(keypoints_path, cameras, truth_path):
    """The learned landmarks a result was solved with (keypoints.npz), triangulated on their own per frame
    (left/right swaps resolved across views as the tracker does) -> (frames, errors (F,12) metres) against
    the truth's joints of TRIANGULATION_JOINTS, and those joints' names. The baseline the tracker must beat."""
    from ..evidence.keypoint_fit import resolve_swaps, triangulate

    with np.load(keypoints_path) as d:
        frames, uv, vis = d["frames"].astype(np.int64), d["uv"], d["visibility"]
    t_names, t_frames, t_pos = load_joints(truth_path)
    joints = list(TRIANGULATION_JOINTS)
    ti = joint_indices(t_names, str(truth_path))[[list(EVAL_JOINTS).index(j) for j in joints]]
    landmarks = np.array([TRIANGULATION_JOINTS[j] for j in joints])
    swap = np.array([joints.index(j.replace("l_", "r_") if j.startswith("l_") else j.replace("r_", "l_"))
                     for j in joints])
    common, k_at, t_at = np.intersect1d(frames, t_frames, return_indices=True)
    errors = []
    for k, t in zip(k_at, t_at):
        weight = np.where(vis[k][:, landmarks] > 0, 0.25 + 0.75 * vis[k][:, landmarks], 0.0)
        points, weight = resolve_swaps(cameras, uv[k][:, landmarks], weight, swap)
        X, ok = triangulate(cameras, points, weight)
        errors.append(np.where(ok, np.linalg.norm(X - t_pos[t][ti], axis=1), np.nan))
    return common, np.array(errors), joints
