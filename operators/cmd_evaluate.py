"""`evaluate`: 3D error of a result folder against ground-truth joints."""
import sys
from pathlib import Path

from ..core.evaluation import EvaluationError, joint_errors, plot_per_frame, summarise


def add_arguments(p):
    p.add_argument("--result", type=Path, required=True, help="result folder (holding joints.npz)")
    p.add_argument("--truth", type=Path, required=True, help="ground truth joints (gt_joints.npz)")
    p.add_argument("--plot", type=Path, help="per-frame error plot (default: RESULT/error_per_frame.png)")


def evaluate(result_dir, truth, plot=None):
    frames, errors = joint_errors(Path(result_dir) / "joints.npz", truth)
    summary = summarise(frames, errors)
    plot = plot or Path(result_dir) / "error_per_frame.png"
    plot_per_frame(frames, errors, plot)
    return summary, plot


def run(args):
    try:
        summary, plot = evaluate(args.result, args.truth, args.plot)
    except (EvaluationError, FileNotFoundError) as exc:
        print(f"markerless_mocap evaluate: {exc}", file=sys.stderr)
        return 2
    print(f"frames: {summary.frames}")
    print(f"3D error over 15 joints: {summary.mean_mm:.1f} +- {summary.std_mm:.1f} mm (median "
          f"{summary.median_mm:.1f}, max {summary.max_mm:.1f})")
    print(f"PCK@50mm {summary.pck50:.3f}  PCK@100mm {summary.pck100:.3f}")
    print("per joint (mm): " + ", ".join(f"{k} {v:.0f}" for k, v in summary.per_joint_mm.items()))
    print(f"plot: {plot}")
    print(summary.json_line(result=str(args.result)))
    return 0
