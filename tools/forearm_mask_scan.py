"""Scan the forearm's factor against person masks, with or without a wrist in the model, and print where the
least mismatch lies against the actor's true forearm (docs/actor-calibration.md, a wrist in the model).

Each candidate body (the calibration's, its forearm scaled by exp(step), steps -12 % to +12 % by 3 %) gets
its frames refitted to the masks and landmarks by the tracker's local fit from the calibration's poses, then
its XOR / model area (core/actor/body_choice.mask_mismatch, as the calibration's body choice). With --wrist the
model gets two more angles per hand (flexion and deviation of the bone that ends the forearm), so the hand's
outline can bend as the actor's does. Measured (2026-11-26): with the true masks the wrist brings 4 of 7
builds within 3 % (1 of 7 without); with the learned masks 2 of 7. With --trade the length moves between the
upper arm and the forearm at a constant arm span (the elbow slides along the arm, the hand stays): 2026-11-27,
learned masks, calibration frames 0-19 of `calibrate --seed 0`, least mismatch against the truth's forearm share,
per cent: actor -12.2, actor2 +2.6, actor3 -1.1, actor4 +8.7, actor5 -2.1, actor7 -8.5, actor8 -3.4, actor10 -3.7,
actor11 -8.0 (3 of 9 within 3 %; the mismatch moves by 0.001-0.003 over the grid).
With --score edges each candidate's refitted frames are scored by the distance from the arms' outline to the
image's Canny edges instead of the masks' XOR: 2026-11-27, learned masks, frames 0,2,...,18, 3 of 9 within 3 %
with or without the wrist (docs/actor-calibration.md).

    .venv/bin/python tools/forearm_mask_scan.py RESULT:SCENE [RESULT:SCENE ...] [--wrist]
        [--masks true|learned|plate|learned-and-plate] [--frames 0,10,20,29,39] [--threshold 0.5] [--trade]
        [--score masks|edges]

RESULT: a `track --calibrate` result folder (actor.json, poses.npz, keypoints.npz; or a folder holding a
`calibrate` run's actor.json and its calibration_frames' poses.npz and keypoints.npz) of SCENE, a capture folder
with subject.blend and scene_info.json > actor (the true proportions); --masks true also needs gt_masks/ (the
sample scenes have frames 0, 10, 20, 29, 39).
"""
import argparse
import json
from pathlib import Path

import numpy as np

STEPS = np.arange(-4, 5) * 0.03
WRIST_LIMIT = 1.2  # radians either way: a bent wrist, not a broken one
EDGE_CAP = 8.0  # pixels: an outline point farther from every image edge counts as this far (--score edges)


def with_wrist(body):
    """`body` with a flexion and a deviation angle on each hand (the bone that continues the forearm), appended
    after its own DOF so its pose vectors extend with zeros."""
    from markerless_mocap.core.body.model import Body, Dof, DofTarget
    from markerless_mocap.core.evidence.keypoints import end_bone

    extra = []
    for side in "lr":
        hand = end_bone(body, f"{side}_elbow")
        for name, axis in (("flex", (1.0, 0.0, 0.0)), ("deviation", (0.0, 0.0, 1.0))):
            extra.append(Dof(f"{side}_wrist.{name}", "angle", -WRIST_LIMIT, WRIST_LIMIT, f"{side}_elbow", "",
                             [DofTarget(hand, np.array(axis), 1.0)]))
    return Body(body.skeleton, body.dofs + extra, body.vertices, body.faces, body.weights, body.root_bone,
                body.roles, body.preset), len(extra)


def arm_traded(proportions, rig_lengths, t):
    """`proportions` with the forearm x exp(t) and the upper arm shorter by the length the forearm gained."""
    from markerless_mocap.core.actor.proportions import Proportions

    factors = dict(proportions.factors)
    gained = rig_lengths["forearm"] * proportions.factor("forearm") * (np.exp(t) - 1.0)
    factors["forearm"] = proportions.factor("forearm") * float(np.exp(t))
    factors["upper_arm"] = proportions.factor("upper_arm") - gained / rig_lengths["upper_arm"]
    return Proportions(factors, proportions.overall)


def scene_masks(kind, scene, tracker, frames, poses, threshold):
    """(per frame one bool mask per camera, the cameras at the masks' resolution)."""
    import cv2

    import markerless_mocap.core.evidence.learned as learned_model
    from markerless_mocap.core.actor.silhouette_fit import calibration_masks

    cams = tracker.capture.cameras
    if kind == "true":
        masks = []
        for f in frames:
            views = [cv2.imread(str(scene / "gt_masks" / c.name / f"{f:04d}.png"), cv2.IMREAD_GRAYSCALE) for c in cams]
            if any(v is None for v in views):
                raise SystemExit(f"{scene.name}: no true mask of frame {f} in gt_masks/ (use --frames)")
            masks.append([v > 127 for v in views])
        return masks, cams
    learned_model.MASK_THRESHOLD = threshold
    learned, learned_cams = calibration_masks(tracker, frames, poses)
    if kind == "learned":
        return learned, learned_cams
    plate = [[np.asarray(tracker.backgrounds[c.name].silhouette(img[c.name]), bool) for c in cams]
             for img in (tracker.capture.frames.read(f) for f in frames)]
    if kind == "plate":
        return plate, cams
    return [[m & (cv2.resize(p.astype(np.uint8), m.shape[::-1], interpolation=cv2.INTER_AREA) > 0)
             for m, p in zip(lf, pf)] for lf, pf in zip(learned, plate)], learned_cams


def edge_mismatch(model, proxy, cameras, masks, candidates, keypoints, resolution, images):
    """Per candidate (Proportions, start poses): its frames refitted as core/actor/body_choice.mask_mismatch does,
    then the mean distance in pixels (capped at EDGE_CAP) from the arms' outline where it meets the background to
    the nearest Canny edge of the image (images: per frame one BGR image per camera, at the cameras' resolution).
    Sharp where the learned masks are soft: the rendered hand's outline ends on an image edge."""
    import cv2

    from markerless_mocap.core.actor.silhouette_fit import refit_poses, scaled_proxy
    from markerless_mocap.core.render import reference

    def distance_to_edges(image):
        edges = cv2.Canny(cv2.GaussianBlur(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), (3, 3), 0), 40, 120)
        return cv2.distanceTransform((edges == 0).astype(np.uint8), cv2.DIST_L2, 3)

    edge_distance = [[distance_to_edges(im) for im in frame] for frame in images]
    arms = [model.part_names.index(f"{side}_elbow") + 1 for side in "lr"]
    costs = []
    for proportions, start in candidates:
        body, scaled = scaled_proxy(model, proxy, proportions)
        poses = refit_poses(body, scaled, cameras, masks, np.asarray(start, float), keypoints, resolution)
        label = (np.asarray(scaled.face_part) + 1).astype(np.int16)
        distances = []
        for pose, frame_distance in zip(poses, edge_distance):
            uv, z = reference.project_views(body.deform(pose[None], None, body.vertices, body.weights,
                                                        body.unweighted), cameras)
            for c, cam in enumerate(cameras):
                labels = reference.rasterize(uv[0, c], z[0, c], scaled.faces, label, cam.width, cam.height)
                beside_background = cv2.dilate((labels == 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
                outline = reference.boundary_mask(labels) & np.isin(labels, arms) & beside_background
                distances.append(np.minimum(frame_distance[c][outline], EDGE_CAP))
        costs.append(float(np.concatenate(distances).mean()))
    return costs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="+")
    ap.add_argument("--wrist", action="store_true", help="add two angles per hand to the model")
    ap.add_argument("--masks", choices=("true", "learned", "plate", "learned-and-plate"), default="true")
    ap.add_argument("--frames", default="0,10,20,29,39")
    ap.add_argument("--threshold", type=float, default=0.5, help="the learned masks' person probability")
    ap.add_argument("--trade", action="store_true",
                    help="trade length between upper arm and forearm at a constant arm span (shoulder to wrist) "
                         "instead of scaling the forearm alone")
    ap.add_argument("--score", choices=("masks", "edges"), default="masks",
                    help="each candidate's refitted frames scored by XOR against the masks, or by the distance from "
                         "the arms' outline to the image's edges")
    args = ap.parse_args(argv)
    import bpy

    from markerless_mocap.addon.scene_bridge import body_from_blender, find_armature
    from markerless_mocap.core.actor.body_choice import mask_mismatch
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.keypoints import rig_keypoints
    from markerless_mocap.core.actor.proportions import Proportions, segment_lengths
    from markerless_mocap.core.actor.landmark_fit import targets_from_landmarks
    from markerless_mocap.core.tracking.settings import TrackingSettings
    from markerless_mocap.core.tracking.tracker import Tracker

    frames = [int(f) for f in args.frames.split(",")]
    errors = []
    for pair in args.pairs:
        result, scene = (Path(p) for p in pair.split(":"))
        bpy.ops.wm.open_mainfile(filepath=str(scene / "subject.blend"))
        body = body_from_blender(find_armature(bpy.context.scene), None, bpy.context.scene)
        actor = json.loads((result / "actor.json").read_text())
        calibrated = Proportions(actor["factors"], actor["overall"])
        truth = json.loads((scene / "scene_info.json").read_text())["actor"]["proportions"]
        wanted = np.log(Proportions(truth["factors"], truth["overall"]).factor("forearm")
                        / calibrated.factor("forearm"))
        with np.load(result / "poses.npz") as z:
            rows = [list(z["frames"]).index(f) for f in frames]
            poses = z["poses"][rows]
        with np.load(result / "keypoints.npz") as z:
            rig = rig_keypoints(body)
            keypoints = [targets_from_landmarks(z["uv"][i], z["visibility"][i], rig) for i in rows]
        capture = load_capture(scene)
        try:
            tracker = Tracker(body, capture, TrackingSettings(backend="fast"))
            masks, cams = scene_masks(args.masks, scene, tracker, frames, poses, args.threshold)
            scale = cams[0].width / capture.cameras[0].width
            model = body
            if args.wrist:
                model, n_extra = with_wrist(body)
                poses = np.concatenate([poses, np.zeros((len(poses), n_extra))], axis=1)
            if args.trade:
                rig_lengths = segment_lengths(body)
                candidates = [arm_traded(calibrated, rig_lengths, s) for s in STEPS]
                true_lengths = json.loads((scene / "scene_info.json").read_text())["actor"]["true_segment_lengths_m"]
                wanted = np.log(true_lengths["forearm"] / (true_lengths["upper_arm"] + true_lengths["forearm"])
                                / (calibrated.factor("forearm") * rig_lengths["forearm"]
                                   / (calibrated.factor("upper_arm") * rig_lengths["upper_arm"]
                                      + calibrated.factor("forearm") * rig_lengths["forearm"])))
            else:
                candidates = [Proportions({k: (v * np.exp(s) if k.endswith("forearm") else v)
                                           for k, v in calibrated.factors.items()}, calibrated.overall)
                              for s in STEPS]
            refit = (model, tracker.proxy, cams, masks, [(c, poses) for c in candidates],
                     [k.scaled(scale) for k in keypoints], scale / tracker.scale)
            if args.score == "edges":
                import cv2

                images = [[cv2.resize(img[c.name], (c.width, c.height), interpolation=cv2.INTER_AREA) for c in cams]
                          for img in (capture.frames.read(f) for f in frames)]
                costs = edge_mismatch(*refit, images)
            else:
                costs = mask_mismatch(*refit, "fast")
        finally:
            capture.close()
        best = STEPS[int(np.argmin(costs))]
        errors.append(100 * (best - wanted))
        print(f"{scene.name}: " + " ".join(f"{s:+.2f}:{c:.4f}" for s, c in zip(STEPS, costs))
              + f" | least at {best:+.2f}, the truth at {wanted:+.3f}: {errors[-1]:+.1f} %", flush=True)
    print(f"{args.masks} masks{', scored by edges' if args.score == 'edges' else ''}, "
          f"{'with' if args.wrist else 'without'} the wrist: within 3 % on "
          f"{sum(abs(e) <= 3 for e in errors)} of {len(errors)}")


if __name__ == "__main__":
    main()
