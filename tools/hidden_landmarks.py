"""How good are the landmarks of limbs the actor's own body hides? The landmark model still places a point it cannot
see (and its visibility score often stays near 1): this measures how far such points lie from the truth against
the visible ones, per rig point.

For every frame of SCENE (a rendered capture with gt_joints.npz) the true pose is fitted to the true joints; the
body posed as the truth's previous frame (what a tracker that has been right so far predicts) is drawn into a
z-buffer per camera at a quarter of the capture's size, and a rig point counts as hidden in a view when a surface
lies more than --margin metres nearer that camera than the point. Each landmark of RESULT's keypoints.npz (what
that run was solved with) is scored by its distance to the truth's rig point, as a share of the person's size in
that view (the larger side of the truth's projected points). Printed: the share of hidden landmarks, the median
and 75th percentile of the distance hidden against visible, and the median visibility score, per rig point.

    .venv/bin/python tools/hidden_landmarks.py sample_scenes/sit RESULT [--margin 0.1]

docs/measurements.md, "Tried and not adopted" ("Sit's left arm"), quotes it.
"""
import argparse
from pathlib import Path

import numpy as np

# BlazePose's names of the landmarks the rig points stand for (core/evidence/keypoints.py, LANDMARK_POINTS)
LANDMARK_NAMES = {0: "nose", 11: "left shoulder", 12: "right shoulder", 13: "left elbow", 14: "right elbow",
                  15: "left wrist", 16: "right wrist", 23: "left hip", 24: "right hip", 25: "left knee",
                  26: "right knee", 27: "left ankle", 28: "right ankle", 31: "left foot index",
                  32: "right foot index"}


def hidden_in_view(vertices, faces, camera, points, margin):
    """(K,) bool: the world `points` (K,3) behind the mesh (`vertices` V,3 world, `faces` F,3) in `camera` by more
    than `margin` metres; a point outside the picture or behind the camera is not hidden."""
    from markerless_mocap.core.render.rim import depth_buffer

    uv, z = camera.project_with_depth(vertices)
    depth = depth_buffer(uv, z, faces, camera.width, camera.height)
    puv, pz = camera.project_with_depth(points)
    col, row = np.round(puv[:, 0]).astype(int), np.round(puv[:, 1]).astype(int)
    inside = (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height) & (pz > 0)
    front = depth[np.clip(row, 0, camera.height - 1), np.clip(col, 0, camera.width - 1)]
    return inside & (front < pz - margin)


def truth_and_landmarks(scene, result):
    """The scene's subject body (bpy), its rig points, the truth's frames and poses on it, the cameras, and the
    result's landmarks per frame in the cameras' order: (body, rig, frames, poses, cameras, uv, visibility,
    landmark frames). tools/landmark_facing.py reads the same."""
    import bpy

    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.body.pose_fit import poses_from_joints
    from markerless_mocap.core.capture.calibration import find_calibration_file, read_calibration
    from markerless_mocap.core.evidence.keypoints import rig_keypoints
    from markerless_mocap.core.results.result_folder import load_joints

    bpy.ops.wm.open_mainfile(filepath=str(scene / "subject.blend"))
    body = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
    names, frames, positions = load_joints(scene / "gt_joints.npz")
    poses, _ = poses_from_joints(body, names, positions)
    cameras = read_calibration(find_calibration_file(scene))
    with np.load(result / "keypoints.npz") as saved:
        order = [list(saved["cameras"]).index(c.name) for c in cameras]
        uv, visibility, landmark_frames = saved["uv"][:, order], saved["visibility"][:, order], saved["frames"]
    return body, rig_keypoints(body), frames, poses, cameras, uv, visibility, landmark_frames


def measure(scene, result, margin, scale=0.25):
    """Rows (frame, camera, point, hidden, distance share, visibility) and the rig points' landmark numbers."""
    body, rig, frames, poses, cameras, uv_all, vis_all, _ = truth_and_landmarks(scene, result)
    rows = []
    for i in range(1, len(frames)):
        vertices = body.deform(poses[i - 1][None])[0]
        expected = rig.world(body, poses[i - 1][None])[0]
        true_points = rig.world(body, poses[i][None])[0]
        for c, cam in enumerate(cameras):
            hidden = hidden_in_view(vertices, body.faces, cam.scaled(scale), expected, margin)
            truth_uv = cam.project(true_points)
            size = np.ptp(truth_uv, axis=0).max()
            uv, vis = uv_all[i, c][rig.landmarks], vis_all[i, c][rig.landmarks]
            share = np.linalg.norm(uv - truth_uv, axis=1) / size
            for k in range(len(rig.landmarks)):
                if np.isfinite(share[k]):
                    rows.append((frames[i], c, k, hidden[k], share[k], vis[k]))
    return np.array(rows, dtype=float), rig.landmarks


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", type=Path)
    ap.add_argument("result", type=Path, help="a track result folder of that scene (its keypoints.npz)")
    ap.add_argument("--margin", type=float, default=0.1, help="metres a surface must lie in front (default 0.1)")
    args = ap.parse_args(argv)
    rows, landmarks = measure(args.scene, args.result, args.margin)
    hidden = rows[:, 3] > 0
    print(f"{args.scene.name}: {hidden.mean():.3f} of the landmarks hidden (margin {args.margin} m)")
    print("point            hidden   distance hidden: median / p75   visible: median / p75   visibility hidden")
    for k, lm in enumerate(landmarks):
        mine = rows[:, 2] == k
        h, v = rows[mine & hidden], rows[mine & ~hidden]

        def stat(a):
            return f"{np.median(a[:, 4]):.3f} / {np.percentile(a[:, 4], 75):.3f}" if len(a) else "   -   /   -  "

        vis = f"{np.median(h[:, 5]):.2f}" if len(h) else "-"
        print(f"{LANDMARK_NAMES[lm]:16s} {mine[hidden].sum() / max(mine.sum(), 1):6.2f}   {stat(h):>22s}   "
              f"{stat(v):>22s}   {vis}")


if __name__ == "__main__":
    main()
