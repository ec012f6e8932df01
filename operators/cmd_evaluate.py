"""`evaluate`: a result folder against ground-truth joints, or, without ground truth (real footage),
against the learned evidence found afresh around its poses; optionally a contact sheet of the overlays."""
import json
import zipfile
from pathlib import Path

import numpy as np

from ..core.results.evaluation import EVAL_JOINTS, EvaluationError, joint_errors, plot_per_frame, summarise
from .failures import USER_ERRORS, cli_failure


def add_arguments(p):
    p.add_argument("--result", type=Path, required=True,
                   help="result folder (holding joints.npz, poses.npz); of several actors: OUT/actors/NAME, or OUT "
                        "itself with --capture (each actor measured, the sheet draws them all)")
    p.add_argument("--truth", type=Path, help="ground truth joints (gt_joints.npz; a result of several actors: the "
                                              "folder holding gt_joints_<armature>.npz); without it, the agreement "
                                              "with the learned evidence is measured (needs --capture)")
    p.add_argument("--capture", type=Path, help="the capture folder the result was tracked on (with --truth: also "
                                                "the error of its landmarks triangulated alone, the baseline)")
    p.add_argument("--scene", type=Path, help="SUBJECT.blend tracked (default: CAPTURE/subject.blend)")
    p.add_argument("--sheet", type=Path, help="write a contact sheet PNG: every view, every --every frames")
    p.add_argument("--every", type=int, default=10, help="frame step of the contact sheet (default 10)")
    p.add_argument("--plot", type=Path, help="per-frame error plot (default: RESULT/error_per_frame.png)")


def evaluate(result_dir, truth, plot=None):
    frames, errors = joint_errors(Path(result_dir) / "joints.npz", truth)
    summary = summarise(frames, errors)
    plot = plot or Path(result_dir) / "error_per_frame.png"
    plot_per_frame(frames, errors, plot)
    return summary, plot


def _print_truth(args):
    summary, plot = evaluate(args.result, args.truth, args.plot)
    print(f"frames: {summary.frames}")
    print(f"3D error over 15 joints: {summary.mean_mm:.1f} +- {summary.std_mm:.1f} mm (median "
          f"{summary.median_mm:.1f}, max {summary.max_mm:.1f})")
    print(f"PCK@50mm {summary.pck50:.3f}  PCK@100mm {summary.pck100:.3f}")
    print("per joint (mm): " + ", ".join(f"{k} {v:.0f}" for k, v in summary.per_joint_mm.items()))
    print(f"plot: {plot}")
    extra = {}
    raw = Path(args.result) / "joints_raw.npz"
    if raw.is_file():  # a smoothed take: the poses as solved, for comparison
        _, raw_errors = joint_errors(raw, args.truth)
        extra["raw_mean_mm"] = float(1000 * raw_errors.mean())
        print(f"as solved, before smoothing (joints_raw.npz): {extra['raw_mean_mm']:.1f} mm")
    print(summary.json_line(result=str(args.result), **extra))


def _print_cast_truth(args, cast):
    """Each actor of a result of several actors against its truth: `--truth` a folder holding
    gt_joints_<armature>.npz per actor (the sample scenes' layout); a truth file is one person's."""
    import argparse

    names = ", ".join(name for name, _ in cast)
    if not Path(args.truth).is_dir():
        raise EvaluationError(f"{args.result} holds several actors ({names}) and {args.truth} is one person's truth: "
                              f"give the folder holding gt_joints_<armature>.npz for each, or one actor's folder with "
                              f"its truth, --result {Path(args.result) / 'actors' / cast[0][0]}")
    truths = [Path(args.truth) / f"gt_joints_{name}.npz" for name, _ in cast]
    missing = [str(t) for t in truths if not t.is_file()]
    if missing:
        raise EvaluationError(f"no truth for {len(missing)} of the actors ({names}): {', '.join(missing)} missing")
    for (name, folder), truth in zip(cast, truths):
        print(f"{name} ({folder}):")
        one = argparse.Namespace(**{**vars(args), "result": folder, "truth": truth, "plot": None})
        _print_truth(one)
        if args.capture is not None:
            _print_triangulation(one)


def _print_triangulation(args):
    """The same joints from the result and from triangulating its landmarks alone (needs --capture)."""
    from ..core.capture.capture import load_capture
    from ..core.results.evaluation import triangulation_errors

    keypoints = Path(args.result) / "keypoints.npz"
    if not keypoints.is_file():
        raise EvaluationError(f"{keypoints} is missing: the result was tracked without learned evidence")
    capture = load_capture(args.capture)
    frames, tri, joints = triangulation_errors(keypoints, capture.cameras, args.truth)
    t_frames, tracked = joint_errors(Path(args.result) / "joints.npz", args.truth)
    keep = np.isin(t_frames, frames)
    cols = [list(EVAL_JOINTS).index(j) for j in joints]
    tracked_mm = 1000 * tracked[keep][:, cols].mean()
    tri_mm = 1000 * np.nanmean(tri)
    missing = float(np.isnan(tri).mean())
    print(f"the same {len(joints)} limb joints over {len(frames)} frames: tracked {tracked_mm:.1f} mm, landmarks "
          f"triangulated alone {tri_mm:.1f} mm ({100 * missing:.1f} % not triangulated)")
    print(json.dumps({"result": str(args.result), "joints": joints, "tracked_mm": tracked_mm,
                      "triangulated_mm": tri_mm, "not_triangulated": missing}))


def _load_result(result_dir):
    path = Path(result_dir) / "poses.npz"
    try:
        with np.load(path) as d:
            return d["frames"].astype(np.int64), d["poses"]
    except (ValueError, KeyError, zipfile.BadZipFile) as exc:  # numpy's words for a file that is not a result's
        raise EvaluationError(f"{path} is not the poses.npz of a result folder ({exc})") from exc


def _report(result_dir):
    """A result folder's report.json as a dict ({} when it has none that reads)."""
    try:
        report = json.loads((Path(result_dir) / "report.json").read_text())
    except (OSError, ValueError):
        return {}
    return report if isinstance(report, dict) else {}


def cast_actors(result_dir):
    """[(armature name, its result folder)] when `result_dir` holds several actors (its report.json lists them,
    docs/several-actors.md), else None."""
    if (Path(result_dir) / "poses.npz").is_file():
        return None
    actors = _report(result_dir).get("actors")
    return [(a["armature"], Path(result_dir) / a["folder"]) for a in actors] if actors else None


def _subject(args, result_dir):
    from ..addon.scene_bridge import body_from_blender, find_armature
    from .cmd_track import open_subject

    scene = open_subject(args.scene or args.capture / "subject.blend")
    # the result's own armature: a scene of several actors has one per actor
    body = body_from_blender(find_armature(scene, _report(result_dir).get("armature")), None, scene)
    actor_file = Path(result_dir) / "actor.json"
    if actor_file.is_file():  # tracked with an actor calibration: the poses are the actor body's
        from ..core.actor.actor_file import actor_body, load_actor

        body = actor_body(load_actor(actor_file), body)
    return body


def _agreement(result_dir, body, capture, proxy, frames, poses):
    from ..core.evidence.agreement import result_agreement, summarise_agreement
    from ..core.evidence.learned import LandmarkModel
    from ..core.evidence.keypoints import rig_keypoints

    per_view = result_agreement(body, proxy, capture.cameras, capture.frames.read, frames, poses,
                                rig_keypoints(body), LandmarkModel())
    summary = summarise_agreement(per_view)
    print(f"agreement with the learned evidence over {len(frames)} frames (no ground truth):")
    print("| view | mask covers the model | IoU with the mask | keypoint distance (px) |")
    print("|---|---|---|---|")
    for name, s in summary.items():
        print(f"| {name} | {s['coverage']:.3f} | {s['iou']:.3f} | {s['keypoint_px']:.1f} |")
    print(json.dumps({"result": str(result_dir), "frames": len(frames), "agreement": summary}))


def _sheet(args, capture, actors):
    """The contact sheet: every `actors` entry (body, proxy, frames, poses, result folder) drawn over the footage
    with its landmarks, each actor in its own colours, on the first actor's frames."""
    import cv2

    from ..core.results.overlay import actor_colours, contact_sheet, draw_body, draw_landmarks, part_colours

    landmarks, posed = [], []
    for _body, _proxy, frames, poses, result_dir in actors:
        landmarks.append({})
        path = Path(result_dir) / "keypoints.npz"
        if path.is_file():
            with np.load(path) as d:
                landmarks[-1] = {int(f): (uv, vis) for f, uv, vis in zip(d["frames"], d["uv"], d["visibility"])}
        posed.append(dict(zip((int(f) for f in frames), poses)))
    parts = max(len(a[1].part_names) for a in actors)
    colours = [part_colours(parts)] if len(actors) == 1 else actor_colours(len(actors), parts)
    rows, labels = [], []
    for frame in [int(f) for f in actors[0][2]][::max(1, args.every)]:
        images = capture.frames.read(frame)
        cells = [images[cam.name] for cam in capture.cameras]
        for (body, proxy, *_), poses, marks, colour in zip(actors, posed, landmarks, colours):
            if frame not in poses:
                continue
            vertices = proxy.deform(body, poses[frame][None])[0]
            for c, cam in enumerate(capture.cameras):
                cells[c] = draw_body(cells[c], cam, vertices, proxy.faces, proxy.face_part, colour)
                if frame in marks:
                    uv, vis = marks[frame]
                    draw_landmarks(cells[c], uv[c], vis[c])
        rows.append(cells)
        labels.append(f"frame {frame}")
    args.sheet.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.sheet), contact_sheet(rows, label_rows=labels))
    print(f"contact sheet: {args.sheet} ({len(rows)} frames x {len(capture.cameras)} views)")


def run(args):
    try:
        cast = cast_actors(args.result)
        if cast and args.truth is not None:
            _print_cast_truth(args, cast)
        elif args.truth is not None:
            _print_truth(args)
            if args.capture is not None:
                _print_triangulation(args)
        elif args.capture is None:
            raise EvaluationError("give --truth gt_joints.npz, or --capture CAPTURE to measure against the "
                                  "learned evidence when there is no ground truth")
        if args.capture is not None and (args.truth is None or args.sheet is not None):  # no truth: agreement
            from ..core.capture.capture import load_capture
            from ..core.body.proxy import make_proxy

            capture = load_capture(args.capture)
            actors = []
            for name, result_dir in cast or [(None, Path(args.result))]:
                body = _subject(args, result_dir)
                proxy = make_proxy(body)
                frames, poses = _load_result(result_dir)
                if args.truth is None:
                    if name is not None:
                        print(f"{name} ({result_dir}):")
                    _agreement(result_dir, body, capture, proxy, frames, poses)
                actors.append((body, proxy, frames, poses, result_dir))
            if args.sheet is not None:
                _sheet(args, capture, actors)
    except USER_ERRORS as exc:  # EvaluationError, a capture or file that cannot be read: the user's to fix
        return cli_failure("evaluate", exc)
    return 0
