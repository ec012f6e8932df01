"""`compare`: the paper's Table 3 on our captures — every optimiser at the same budget and seeds.

All runs start from the same initial pose (one global ISA search on the first frame, as in the
paper, or with --start truth the ground truth's pose), use the same anatomical prior and the same
number of energy evaluations per frame.
Writes a Markdown table and ends with one JSON line of the figures.
"""
import json
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..core.results.evaluation import joint_errors, summarise
from ..core.results.result_folder import ResultWriter
from ..core.tracking.options import OPTIONS
from ..core.tracking.settings import TrackingSettings
from ..core.tracking.tracker import Tracker, run_tracker
from .cmd_track import Progress, open_subject, parse_frames

class Row(NamedTuple):
    label: str
    algorithm: str
    likelihood: str
    refine: str = "none"  # "icp": the local ICP fit after the optimiser
    # (particles, iterations) of this row; None: --particles x --iterations; "half": half the particles for
    # twice the iterations (100 x 30 at the paper's 200 x 15)
    split: tuple[int, int] | str | None = None


# The paper's six rows run the plain optimisers at 200 x 15 (PF 3000 particles, FSA 3000 steps). ISA also
# runs the same budget as 100 particles x 30 iterations: the paper found 100 particles enough (its Fig. 2c),
# and on our 30 fps captures the longer annealing holds the arms better (walk, seeds 0-8: 27.2 mm against
# 30.5 mm at 200 x 15). The last row is the product's default, ISA followed by the local ICP fit.
DEFAULT_ROWS = (
    Row("PF (s^Ch+c)", "pf", "silhch+color"),
    Row("ICP (s)", "icp", "silh"),
    Row("APF (s^Ch+c)", "apf", "silhch+color"),
    Row("FSA (s^Ch+c)", "fsa", "silhch+color"),
    Row("ISA (s^Ch+c)", "isa", "silhch+color"),
    Row("ISA (s+e)", "isa", "silh+edge"),
    Row("ISA (s+e)", "isa", "silh+edge", split="half"),
    Row("ISA + ICP refinement (s+e)", "isa", "silh+edge", "icp"),
    # Learned evidence (core/evidence/learned.py): the learned person mask for the silhouette, and 2D keypoints.
    Row("ISA (ls+e+kp)", "isa", "lsilh+edge+kp"),
    Row("ISA + ICP refinement (ls+e+kp)", "isa", "lsilh+edge+kp", "icp"),
)


def add_arguments(p):
    p.add_argument("--scene", type=Path, help="SUBJECT.blend (default: CAPTURE/subject.blend)")
    p.add_argument("--capture", type=Path, required=True)
    p.add_argument("--truth", type=Path, help="ground truth joints (default: CAPTURE/gt_joints.npz)")
    p.add_argument("--out", type=Path, default=Path("results/compare"))
    p.add_argument("--frames", help="capture frames A-B (default: all)")
    p.add_argument("--seeds", default="0", help="comma-separated seeds (default: 0)")
    p.add_argument("--particles", type=int, default=200)
    p.add_argument("--iterations", type=int, default=15)
    p.add_argument("--rows", help="subset of rows by algorithm:likelihood, e.g. isa:silh+edge,apf:silhch+color; "
                                  "isa+icp:silh+edge adds the local ICP refinement; isa:silh+edge@100x30 runs "
                                  "100 particles x 30 iterations (the same budget, split differently)")
    p.add_argument("--backend", default=OPTIONS["backend"].default, choices=OPTIONS["backend"].values,
                   help="likelihood backend, as for track (auto: gpu on a hardware GPU, else fast)")
    p.add_argument("--start", choices=("search", "learned", "truth"), default="search",
                   help="common initial pose: a global search on the first frame with silhouettes and edges "
                        "(default, as the paper), the product's own first frame (learned landmarks and mask, "
                        "then the search and the local fit: for captures without a background plate, where "
                        "background subtraction cannot place the body), or the ground truth's pose (fitted to its "
                        "joints; separates tracking from initialisation)")


def _rows(spec, particles, iterations):
    """The rows to run, each with its (particles, iterations) resolved; every row must get the same budget."""
    budget = particles * iterations
    rows = []
    for row in DEFAULT_ROWS if not spec else [_parse_row(item) for item in spec.split(",")]:
        if row.split == "half":
            n, m = particles // 2, iterations * 2
            row = row._replace(split=(n, m), label=f"{row.label}, {n} x {m}")
        rows.append(row)
        if row.split is not None and row.split[0] * row.split[1] != budget:
            raise SystemExit(f"compare: row {row.label!r} runs {row.split[0]} x {row.split[1]} = "
                             f"{row.split[0] * row.split[1]} evaluations per frame, but every row must get the "
                             f"same budget, --particles x --iterations = {budget}: change the split or the budget "
                             f"(an even --particles for the default rows)")
    return rows


def _parse_row(item):
    """'algo[+icp]:likelihood[@NxM]' -> Row."""
    algo, _, lik = item.partition(":")
    algo, _, refine = algo.partition("+")
    lik, _, split_spec = (lik or "silh+edge").partition("@")
    split = None
    if split_spec:
        n, _, m = split_spec.partition("x")
        if not (n.isdigit() and m.isdigit()):
            raise SystemExit(f"compare: --rows item {item!r}: write the split as @PARTICLESxITERATIONS, e.g. @100x30")
        split = (int(n), int(m))
    label = f"{algo.upper()} + ICP refinement ({lik})" if refine else f"{algo.upper()} ({lik})"
    if split:
        label += f", {split[0]} x {split[1]}"
    return Row(label, algo, lik, refine or "none", split)


def run(args):
    from ..addon.scene_bridge import body_from_blender, find_armature
    from ..core.capture.capture import load_capture
    from .track_session import build_motion_models

    from ..core.render import BackendUnavailableError
    from .backend_choice import choose_backend

    try:
        choice = choose_backend(args.backend)
    except BackendUnavailableError as exc:
        print(f"markerless_mocap compare: {exc}", file=sys.stderr)
        return 2
    print(f"likelihood backend: {choice.used} ({choice.reason})", file=sys.stderr)
    args.backend = choice.used
    capture_dir = args.capture
    scene = open_subject(args.scene or capture_dir / "subject.blend")
    truth = args.truth or capture_dir / "gt_joints.npz"
    body = body_from_blender(find_armature(scene), None, scene)
    capture = load_capture(capture_dir)
    frames = list(parse_frames(args.frames) or range(capture.frames.n_frames))
    seeds = [int(s) for s in args.seeds.split(",")]
    budget = args.particles * args.iterations
    rows = _rows(args.rows, args.particles, args.iterations)
    prior, dynamics = build_motion_models(body, capture_dir, capture.frames.fps)
    # One common initial pose per seed (the paper: "the same initial pose is used for all approaches").
    init = {}
    results = []
    for label, algo, lik, refine, split in rows:
        particles, iterations = split or (args.particles, args.iterations)
        for seed in seeds:
            settings = TrackingSettings(algorithm=algo, likelihood=lik, particles=particles, refine=refine,
                                        iterations=iterations, seed=seed, backend=args.backend)
            tracker = Tracker(body, capture, settings, prior=prior, dynamics=dynamics)
            if seed not in init and args.start == "truth":
                init[seed] = true_first_pose(body, truth, frames[0])
            if seed not in init:
                init_settings = (TrackingSettings(seed=seed, backend=args.backend) if args.start == "learned" else
                                 TrackingSettings(likelihood="silh+edge", seed=seed, backend=args.backend))
                init_tracker = Tracker(body, capture, init_settings, prior=prior, proxy=tracker.proxy)
                init[seed] = init_tracker.initialise(frames[0], rough_pose=body.default_pose()).pose
            refined = "_icp" if refine != "none" else ""
            split_name = f"_{particles}x{iterations}" if split else ""
            out = args.out / f"{algo}{refined}_{lik.replace('+', '-')}{split_name}_seed{seed}"
            writer = ResultWriter(out, body, settings, info={"capture": str(capture_dir), "label": label})
            progress = Progress(len(frames))
            print(f"== {label}, seed {seed}", file=sys.stderr)
            t0 = time.perf_counter()

            def on_frame(est, writer=writer, progress=progress):
                writer.add(est)
                progress(est)

            ests = run_tracker(tracker, frames, initial_pose=init[seed], on_frame=on_frame)
            seconds = (time.perf_counter() - t0) / max(1, len(ests) - 1)
            f, e = joint_errors(out / "joints.npz", truth)
            s = summarise(f[1:], e[1:])  # frame 1 is the common initial pose
            results.append({"label": label, "algorithm": algo, "likelihood": lik, "refine": refine, "seed": seed,
                            "particles": particles, "iterations": iterations,
                            "mean_mm": s.mean_mm, "std_mm": s.std_mm, "max_mm": s.max_mm,
                            "seconds_per_frame": seconds,
                            "evaluations_per_frame": float(np.mean([e.evaluations for e in ests[1:]]))})
    table = markdown_table(results, capture_dir, len(frames), budget, seeds, args.start)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "compare.md").write_text(table)
    print(table)
    print(json.dumps({"capture": str(capture_dir), "frames": len(frames), "budget": budget, "seeds": seeds,
                      "start": args.start,
                      "rows": results}))
    return 0


def true_first_pose(body, truth, frame):
    from ..core.body.pose_fit import poses_from_joints
    from ..core.results.result_folder import load_joints

    names, truth_frames, positions = load_joints(truth)
    if frame not in truth_frames:
        raise SystemExit(f"--start truth: {truth} has no frame {frame}")
    try:
        poses, _ = poses_from_joints(body, names, positions[list(truth_frames).index(frame)][None])
    except ValueError as error:
        raise SystemExit(f"--start truth: {error}") from None
    return poses[0]


def markdown_table(results, capture, n_frames, budget, seeds, start="search"):
    origin = {"truth": "the ground truth's first pose", "learned": "the product's first frame (learned evidence)"}.get(
        start, "one global search on the first frame")
    lines = [f"3D error over 15 joints (mm, mean +- std over frames; mean over seeds {seeds}) on {capture}, "
             f"{n_frames} frames, {budget} energy evaluations per frame, all starting from {origin}", "",
             "| optimiser (likelihood) | error (mm) | per seed (mm) | max (mm) | s / frame | evaluations / frame |",
             "|---|---|---|---|---|---|"]
    labels = list(dict.fromkeys(r["label"] for r in results))
    for label in labels:
        rs = [r for r in results if r["label"] == label]
        mean = np.mean([r["mean_mm"] for r in rs])
        std = np.mean([r["std_mm"] for r in rs])
        per_seed = " / ".join(f"{r['mean_mm']:.1f}" for r in rs)
        lines.append(f"| {label} | {mean:.1f} +- {std:.1f} | {per_seed} | {max(r['max_mm'] for r in rs):.0f} | "
                     f"{np.mean([r['seconds_per_frame'] for r in rs]):.2f} | "
                     f"{np.mean([r['evaluations_per_frame'] for r in rs]):.0f} |")
    return "\n".join(lines) + "\n"
