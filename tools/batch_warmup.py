"""How many frames a chunk needs to settle (docs/batch.md, "Warm-up"): a sample scene tracked in one piece and
from later start frames (each start initialised from the landmarks as a chunk's first frame is), compared frame by
frame after each start: the 15 joints' mean distance to the one-piece run, and both runs' error against the truth.

Runs `track-chunk` one chunk at a time (finished chunks are reused), then prints a table per start and a summary:
per frame after the start, the largest distance over the starts.

    .venv/bin/python tools/batch_warmup.py walk --starts 10,20,30,40 --chunks WARMUP_DIR [tracking options]
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="a sample scene's name (sample_scenes/<scene>, with gt_joints.npz)")
    ap.add_argument("--starts", required=True, help="start frames, comma-separated")
    ap.add_argument("--last", type=int, help="the last frame (default: the clip's last)")
    ap.add_argument("--chunks", type=Path, required=True, help="folder for the chunk folders")
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args, options = ap.parse_known_args(argv)

    from markerless_mocap.core.batch.chunk_folder import ChunkFolder
    from markerless_mocap.core.results.evaluation import joint_indices
    from markerless_mocap.core.results.result_folder import load_joints

    scene = REPO / "sample_scenes" / args.scene
    names, gt_frames, gt = load_joints(scene / "gt_joints.npz")
    last = args.last if args.last is not None else int(gt_frames[-1])
    starts = [0] + [int(s) for s in args.starts.split(",")]
    runs = {}
    for start in starts:
        cmd = [sys.executable, "-m", "markerless_mocap", "track-chunk", "--scene", str(scene / "subject.blend"),
               "--capture", str(scene), "--take", args.scene, "--frames", f"{start}-{last}", "--chunks",
               str(args.chunks), *options]
        print(" ".join(cmd), file=sys.stderr, flush=True)
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
        folder = ChunkFolder(args.chunks, args.scene, (start, last), Path(out).name.rsplit("_", 1)[1])
        runs[start] = folder.estimates()
    bone_names, _, _ = load_joints(folder.path / "joints.npz")
    mine, truth = joint_indices(bone_names, "the subject"), joint_indices(names, "the ground truth")
    gt_at = {int(f): gt[i][truth] for i, f in enumerate(gt_frames)}

    def joints(est):
        return est.joints[mine]

    figures = {}
    for start in starts[1:]:
        rows = []
        for f in range(start, last + 1):
            a, b = joints(runs[start][f]), joints(runs[0][f])
            rows.append({"after": f - start, "frame": f, "to_one_piece_mm": float(np.linalg.norm(a - b, axis=1).mean()
                                                                                 * 1e3),
                         "chunk_error_mm": float(np.linalg.norm(a - gt_at[f], axis=1).mean() * 1e3),
                         "one_piece_error_mm": float(np.linalg.norm(b - gt_at[f], axis=1).mean() * 1e3)})
        figures[start] = rows
        print(f"\nstart {start}: frames after the start, 15-joint mean distance to the one-piece run (mm) "
              "[chunk / one-piece error vs truth]")
        print("  " + "  ".join(f"{r['after']}:{r['to_one_piece_mm']:.1f}[{r['chunk_error_mm']:.0f}/"
                               f"{r['one_piece_error_mm']:.0f}]" for r in rows))
    longest = max(len(v) for v in figures.values())
    worst = [max(v[k]["to_one_piece_mm"] for v in figures.values() if k < len(v)) for k in range(longest)]
    print("\nlargest distance over the starts, per frame after the start (mm):")
    print("  " + " ".join(f"{k}:{w:.1f}" for k, w in enumerate(worst)))
    if args.json:
        args.json.write_text(json.dumps({"scene": args.scene, "last": last, "options": options,
                                         "per_start": figures, "worst": worst}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
