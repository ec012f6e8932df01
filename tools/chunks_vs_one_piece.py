"""A take tracked in chunks against the same take in one piece (docs/batch.md, "Measured"): for each seed, one
`batch` of the sample scenes with ground truth cut into chunks of --chunk-frames, and one with a single chunk per
take (so both are stitched, smoothed and foot-locked alike); then the 15-joint error of each against the truth.

    .venv/bin/python tools/chunks_vs_one_piece.py --out DIR [--scenes walk,busy] [--seeds 0,1,2] [--chunk-frames 30]
                                                  [--workers 1] [--chunk-workers 2]

The one-piece batch runs on --workers processes, the chunked one on --chunk-workers (default: the same), so the
long take's scaling (one process against two) comes out of the same runs, with each batch's wall time.
Finished chunks are reused, so a rerun after an interruption continues (its wall time then counts only what was
left). Prints a table and writes DIR/figures.json. A scene with a truth per actor (gt_joints_<armature>.npz, the duet)
is tracked as a take of those actors, and each actor is a row of its own.
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = ("walk", "playground", "busy", "dusk", "lobby")


def actors_of(scene):
    """The armatures of a scene with a truth per actor (gt_joints_<armature>.npz), else [] (one actor)."""
    return sorted(p.stem.removeprefix("gt_joints_") for p in (REPO / "sample_scenes" / scene).glob("gt_joints_*.npz"))


def takes_file(path, scenes, seed):
    lines = []
    for scene in scenes:
        folder = REPO / "sample_scenes" / scene
        lines += ["[[take]]", f'name = "{scene}"', f'scene = "{folder / "subject.blend"}"',
                  f'capture = "{folder}"', f"seed = {seed}"]
        if actors_of(scene):
            lines.append("armature = [" + ", ".join(f'"{a}"' for a in actors_of(scene)) + "]")
        lines.append("")
    path.write_text("\n".join(lines))
    return path


def rows_of(out, scene, seed):
    """(row name, the result folder, its truth) per actor of a scene's take."""
    actors = actors_of(scene)
    if not actors:
        return [(f"{scene} seed {seed}", out / scene, REPO / "sample_scenes" / scene / "gt_joints.npz")]
    return [(f"{scene} {a} seed {seed}", out / scene / "actors" / a, REPO / "sample_scenes" / scene /
             f"gt_joints_{a}.npz") for a in actors]


def mean_error(result, truth, file="joints.npz"):
    from markerless_mocap.core.results.evaluation import joint_indices
    from markerless_mocap.core.results.result_folder import load_joints

    names, frames, solved = load_joints(result / file)
    gt_names, gt_frames, truth = load_joints(truth)
    at = {int(f): i for i, f in enumerate(gt_frames)}
    mine, theirs = joint_indices(names, "the result"), joint_indices(gt_names, "the truth")
    rows = [at[int(f)] for f in frames]
    return float(np.linalg.norm(solved[:, mine] - truth[rows][:, theirs], axis=-1).mean() * 1e3)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--chunk-frames", type=int, default=30)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--chunk-workers", type=int, default=None)
    args = ap.parse_args(argv)
    scenes, seeds = args.scenes.split(","), [int(s) for s in args.seeds.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    saved = args.out / "figures.json"
    figures = json.loads(saved.read_text()) if saved.is_file() else {}  # other seeds' runs into the same folder
    for seed in seeds:
        takes = takes_file(args.out / f"takes_seed{seed}.toml", scenes, seed)
        chunk_workers = args.workers if args.chunk_workers is None else args.chunk_workers
        for how, chunk, workers in (("one_piece", 100000, args.workers), ("chunks", args.chunk_frames, chunk_workers)):
            out = args.out / f"seed{seed}_{how}"
            cmd = [sys.executable, "-m", "markerless_mocap", "batch", str(takes), "--out", str(out),
                   "--chunk-frames", str(chunk), "--workers", str(workers), "--no-overlays", "--no-export"]
            print(" ".join(cmd), file=sys.stderr, flush=True)
            started = time.monotonic()
            subprocess.run(cmd, check=True)
            wall_s = time.monotonic() - started
            for scene in scenes:
                for name, result, truth in rows_of(out, scene, seed):
                    row = figures.setdefault(name, {})
                    row[f"{how}_wall_s_whole_batch"] = round(wall_s, 1)
                    row[f"{how}_workers"] = workers
                    row[how] = mean_error(result, truth)
                    row[f"{how}_as_solved"] = mean_error(result, truth, "joints_raw.npz")
                    if how == "chunks":
                        report = json.loads((result / "report.json").read_text())
                        row["overlap_mean_joint_mm"] = report.get("batch", {}).get("overlap_mean_joint_mm")
        saved.write_text(json.dumps(figures, indent=1))
    print(f"{'take':<26} {'one piece':>10} {'chunks':>8} {'diff':>6} {'overlap':>8}   (mm, smoothed and foot-locked)"
          "   wall s of the whole batch: one piece / chunks")
    for take, row in figures.items():
        overlap = row.get("overlap_mean_joint_mm")
        walls = [row.get(f"{how}_wall_s_whole_batch") for how in ("one_piece", "chunks")]
        print(f"{take:<26} {row['one_piece']:>10.2f} {row['chunks']:>8.2f} {row['chunks'] - row['one_piece']:>+6.2f} "
              f"{'' if overlap is None else f'{overlap:.2f}':>8}   {walls[0]} / {walls[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
