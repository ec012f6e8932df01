"""Foot slide of a tracked take against the truth's: what foot locking (core/tracking/foot_lock.py) is judged by.

Planted: a foot point (ankle, ball of the foot) of the TRUTH within --planted-height of the floor (z = 0; its height
less its clearance, the point's height above the sole at rest) and slower along the floor than --planted-speed, on
two consecutive frames. Slide: how far the point moves along the floor between those two frames, averaged over
every such pair of every point: the truth's own, the take before foot locking (joints_unpinned.npz, or joints.npz
when the folder has none) and the locked take (joints.npz). Also the lowest foot point (the truth's too) and the
mean 15-joint error of both takes (core/results/evaluation.py).

    .venv/bin/python tools/foot_slide.py RESULT sample_scenes/walk/gt_joints.npz [--scene SUBJECT.blend]

The clearances come from the result's report.json (foot_locking) or, without it, from the subject .blend (--scene,
by default subject.blend beside the truth file).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

PLANTED_HEIGHT = 0.03  # metres above the floor
PLANTED_SPEED = 0.2    # m/s along it (6.7 mm per frame at 30 fps)


def clearances(result, scene):
    """{bone name: clearance (m)} of the feet's contact points: report.json's, else the subject's."""
    report = result / "report.json"
    if report.is_file():
        locking = json.loads(report.read_text()).get("foot_locking")
        if locking and locking.get("clearance_m"):
            return locking["clearance_m"]
    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.tracking.foot_contact import feet
    from markerless_mocap.operators.cmd_track import open_subject

    scene_obj = open_subject(scene)
    body = body_from_blender(find_armature(scene_obj), None, scene_obj)
    return {name: float(c) for foot in feet(body) for name, c in zip(foot.names, foot.clearance)}


def figures(result, truth, scene=None, planted_height=PLANTED_HEIGHT, planted_speed=PLANTED_SPEED):
    """{"slide_mm": {truth, unpinned, locked}, "lowest_mm": {truth, unpinned, locked}, "error_mm": {unpinned, locked},
    "planted_pairs": n} for a result folder and its gt_joints.npz."""
    from markerless_mocap.core.results.evaluation import joint_errors
    from markerless_mocap.core.results.result_folder import load_joints
    from markerless_mocap.core.tracking.foot_contact import along_floor_speed

    result, truth = Path(result), Path(truth)
    unpinned_path = result / "joints_unpinned.npz"
    takes = {"unpinned": unpinned_path if unpinned_path.is_file() else result / "joints.npz",
             "locked": result / "joints.npz"}
    clear = clearances(result, Path(scene) if scene else truth.parent / "subject.blend")
    t_names, t_frames, t_pos = load_joints(truth)
    with np.load(truth) as data:
        fps = float(data["fps"]) if "fps" in data.files else 30.0
    up = np.array([0.0, 0.0, 1.0])
    out = {"slide_mm": {}, "lowest_mm": {}, "error_mm": {}, "planted_pairs": 0,
           "planted": {"height_m": planted_height, "speed_m_s": planted_speed}}
    loaded = {k: load_joints(p) for k, p in takes.items()}
    common = t_frames
    for _, frames, _ in loaded.values():
        common = np.intersect1d(common, frames)
    consecutive = np.diff(common) == 1
    slides = {"truth": []} | {k: [] for k in takes}
    for bone, c in clear.items():
        tp = t_pos[np.searchsorted(t_frames, common), t_names.index(bone)]
        planted = (tp[:, 2] - c < planted_height) & (along_floor_speed(tp, fps, up) < planted_speed)
        pairs = planted[1:] & planted[:-1] & consecutive
        out["planted_pairs"] += int(pairs.sum())
        out["lowest_mm"]["truth"] = min(out["lowest_mm"].get("truth", np.inf), 1000 * float((tp[:, 2] - c).min()))
        slides["truth"].append(np.linalg.norm(np.diff(tp[:, :2], axis=0), axis=1)[pairs])
        for k, (names, frames, pos) in loaded.items():
            p = pos[np.searchsorted(frames, common), names.index(bone)]
            slides[k].append(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1)[pairs])
            lowest = float((p[:, 2] - c).min())
            out["lowest_mm"][k] = min(out["lowest_mm"].get(k, np.inf), 1000 * lowest)
    for k, values in slides.items():
        values = np.concatenate(values)
        out["slide_mm"][k] = float(1000 * values.mean()) if len(values) else None
    for k, path in takes.items():
        out["error_mm"][k] = float(1000 * joint_errors(path, truth)[1].mean())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("result", type=Path, help="a track result folder")
    ap.add_argument("truth", type=Path, help="the scene's gt_joints.npz")
    ap.add_argument("--scene", type=Path, help="the subject .blend (default: subject.blend beside the truth)")
    ap.add_argument("--planted-height", type=float, default=PLANTED_HEIGHT, metavar="M")
    ap.add_argument("--planted-speed", type=float, default=PLANTED_SPEED, metavar="M_S")
    args = ap.parse_args(argv)
    f = figures(args.result, args.truth, args.scene, args.planted_height, args.planted_speed)
    s, low, err = f["slide_mm"], f["lowest_mm"], f["error_mm"]
    print(f"planted foot slide (mm per frame, {f['planted_pairs']} planted frame pairs of the truth): truth "
          f"{s['truth']:.2f}, unpinned {s['unpinned']:.2f}, locked {s['locked']:.2f}")
    print(f"lowest foot point against the floor (mm): truth {low['truth']:.1f}, unpinned {low['unpinned']:.1f}, "
          f"locked {low['locked']:.1f}")
    print(f"mean 15-joint error (mm): unpinned {err['unpinned']:.2f}, locked {err['locked']:.2f} "
          f"({err['locked'] - err['unpinned']:+.2f})")
    print(json.dumps({"result": str(args.result), **f}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
