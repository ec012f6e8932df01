"""Place the sample subject at the person's first-frame position in a real capture (Pose2Sim's demo).

    .venv/bin/python sample_scenes/place_pose2sim.py [--capture sample_scenes/pose2sim_demo] [--data ../shared/data]

There is no ground truth, so the position comes from the images: the bundled BlazePose landmark
model (core/data/models, run through OpenCV's DNN) finds the person in every view of the first
frames - a square crop of the whole image first, then twice a crop around the landmarks it found -
and the hips, shoulders and heels are triangulated (linear DLT on undistorted pixels, weighted by
visibility). The hips' midpoint gives the root, the hip and shoulder lines give the facing, the heels
the floor under the feet. subject.blend is the same MakeHuman subject as the other scenes (built by
subject.py), in the rest pose, put there; how it was found goes into scene_info.json.
Like generate.py, this reads the shared data folder (makehuman/); the product does not.
"""
import argparse
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

import cv2  # noqa: E402

import generate  # noqa: E402  (bpy, the subject builder and save_subject_blend)
import subject  # noqa: E402
from core.capture.capture import load_capture  # noqa: E402

MODEL = REPO / "core" / "data" / "models" / "pose_landmark_full.tflite"
SIDE = 256
L_SHOULDER, R_SHOULDER, L_HIP, R_HIP, L_HEEL, R_HEEL = 11, 12, 23, 24, 29, 30
USED = {"left_shoulder": L_SHOULDER, "right_shoulder": R_SHOULDER, "left_hip": L_HIP, "right_hip": R_HIP,
        "left_heel": L_HEEL, "right_heel": R_HEEL, "left_ankle": 27, "right_ankle": 28}


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def run_crop(net, img, centre, side):
    """Landmarks (33, 2) in image pixels, visibility (33,), presence (33,) for a square crop."""
    s = side / SIDE
    A = np.array([[1 / s, 0, -(centre[0] - side / 2) / s], [0, 1 / s, -(centre[1] - side / 2) / s]])
    crop = cv2.warpAffine(img, A, (SIDE, SIDE), flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT)
    blob = cv2.cvtColor(crop, cv2.COLOR_BGR2RGB).astype(np.float32).transpose(2, 0, 1)[None] / 255.0
    net.setInput(blob)
    out = net.forward("Identity").reshape(39, 5)[:33]
    uv = out[:, :2] * s + (np.asarray(centre) - side / 2)
    return uv, sigmoid(out[:, 3]), sigmoid(out[:, 4])


def detect(net, img, rounds=3):
    """Whole image as a square first, then crops around what was found (1.4 x the landmarks' box)."""
    h, w = img.shape[:2]
    centre, side = np.array([w / 2, h / 2]), float(max(w, h))
    for _ in range(rounds):
        uv, vis, pres = run_crop(net, img, centre, side)
        good = vis > 0.5
        pts = uv[good] if good.sum() >= 8 else uv
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre, side = (lo + hi) / 2, float(1.4 * max(hi - lo))
    return uv, vis, pres, (centre.tolist(), side)


def triangulate(cams, uv, w):
    """Weighted linear DLT of one point from undistorted pixels uv[k] in cams[k] (weights w[k])."""
    rows = []
    for cam, p, wk in zip(cams, uv, w):
        q = cam.undistort_points(p[None])[0]
        P = cam.K @ np.hstack([cam.R, cam.t[:, None]])
        rows += [wk * (q[0] * P[2] - P[0]), wk * (q[1] * P[2] - P[1])]
    _, _, vt = np.linalg.svd(np.array(rows))
    X = vt[-1]
    return X[:3] / X[3]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--capture", default=str(HERE / "pose2sim_demo"))
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--frames", type=int, default=3, help="first frames whose triangulations are averaged")
    args = ap.parse_args(argv)
    folder = Path(args.capture)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cap = load_capture(folder)
    size_warnings = [str(w.message) for w in caught]
    cams = cap.cameras
    net = cv2.dnn.readNetFromTFLite(str(MODEL))
    per_frame, detections = [], []
    for f in range(args.frames):
        imgs = cap.frames.read(f)
        uvs, viss = [], []
        for cam in cams:
            uv, vis, pres, crop = detect(net, imgs[cam.name])
            uvs.append(uv)
            viss.append(vis)
            if f == 0:
                detections.append(dict(camera=cam.name, crop_centre_px=[round(c, 1) for c in crop[0]],
                                       crop_side_px=round(crop[1], 1),
                                       visibility={k: round(float(vis[i]), 3) for k, i in USED.items()}))
        uvs, viss = np.array(uvs), np.array(viss)
        pts, reproj = {}, {}
        for k, i in USED.items():
            X = triangulate(cams, uvs[:, i], viss[:, i])
            pts[k] = X
            reproj[k] = [float(np.linalg.norm(c.project(X[None])[0] - uvs[j, i])) for j, c in enumerate(cams)]
        # leave-one-view-out spread of the hips' midpoint: how well the views agree
        loo = []
        for drop in range(len(cams)):
            keep = [j for j in range(len(cams)) if j != drop]
            mid = np.mean([triangulate([cams[j] for j in keep], uvs[keep, i], viss[keep, i]) for i in (L_HIP, R_HIP)],
                          axis=0)
            loo.append(mid)
        per_frame.append(dict(points=pts, reproj=reproj, loo=np.array(loo)))
    cap.close()

    P0 = per_frame[0]["points"]
    hips = np.mean([(p["points"]["left_hip"] + p["points"]["right_hip"]) / 2 for p in per_frame], axis=0)
    lat = np.mean([p["points"]["left_hip"] - p["points"]["right_hip"] + p["points"]["left_shoulder"]
                   - p["points"]["right_shoulder"] for p in per_frame], axis=0)
    up = np.array([0.0, 0.0, 1.0])
    lat = lat - (lat @ up) * up
    lat /= np.linalg.norm(lat)
    fwd = np.cross(lat, up)                                  # the person's left x up = forward (Z up)
    yaw0 = math.atan2(fwd[1], fwd[0]) - math.atan2(-1.0, 0.0)  # the rest pose faces -Y
    sole = float(np.mean([min(p["points"]["left_heel"][2], p["points"]["right_heel"][2]) for p in per_frame]))
    spread = max(float(np.linalg.norm(p["loo"] - p["loo"].mean(axis=0), axis=1).max()) for p in per_frame)

    data = subject.load_subject_data(args.data)
    hips_rest_z = float(data["bones"]["Hips"]["head"][2])
    placement = generate.save_subject_blend(data, folder / "subject.blend", hips, yaw0, None, offset=(0.0, 0.0),
                                            dyaw=0.0, fps=cap.frames.fps, floor_z=sole)
    M = np.array(placement["armature_matrix_world"])
    root = M[:3, 3] + M[:3, :3] @ np.array(data["bones"]["Hips"]["head"])
    info = dict(
        scene="pose2sim_demo",
        source="Pose2Sim 0.10.49 wheel, Pose2Sim/Demo_SinglePerson (BSD-3-Clause, see SOURCE.txt)",
        cameras=[c.name for c in cams], image_sizes={c.name: list(c.size) for c in cams},
        calibration_size_warnings=size_warnings, fps=cap.frames.fps, n_frames=cap.frames.n_frames,
        ground_truth=None,
        placement_method=(
            "BlazePose full landmark model (core/data/models) in every view of frames 0.."
            f"{args.frames - 1}: a square crop of the whole image, then twice a square crop of 1.4 x the box of the "
            "landmarks found; hips, shoulders, ankles and heels triangulated by visibility-weighted linear DLT on "
            "undistorted pixels. Root: the mean over those frames of the hips' midpoint; facing: forward = "
            "(left - right of hips + shoulders, horizontal) x up; the rig's soles at the heels' mean lowest height. "
            "subject.blend: the MakeHuman subject of the other scenes (subject.py), rest pose, placed there with no "
            "added error."),
        first_frame_landmarks_m={k: np.round(v, 4).tolist() for k, v in P0.items()},
        first_frame_reprojection_px={k: [round(e, 1) for e in v] for k, v in per_frame[0]["reproj"].items()},
        first_frame_detections=detections,
        hips_midpoint_m=np.round(hips, 4).tolist(), facing_yaw_deg=round(math.degrees(yaw0), 2),
        sole_height_m=round(sole, 4), hips_leave_one_view_out_spread_m=round(spread, 4),
        rig_hips_head_m=np.round(root, 4).tolist(), rig_hips_rest_height_m=hips_rest_z,
        rig_hips_minus_landmark_hips_m=np.round(root - hips, 4).tolist(),
        subject_placement=placement)
    (folder / "scene_info.json").write_text(json.dumps(info, indent=1))
    print(json.dumps({k: info[k] for k in ("hips_midpoint_m", "facing_yaw_deg", "sole_height_m",
                                           "hips_leave_one_view_out_spread_m", "rig_hips_minus_landmark_hips_m",
                                           "first_frame_reprojection_px")}, indent=1))


if __name__ == "__main__":
    main()
