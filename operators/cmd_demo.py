"""`demo`: track the bundled sample scene end to end and print its error against the ground truth.

A shorter run than the paper's (fewer frames, a smaller budget) so it finishes in a few minutes on
a 2-core laptop; it says so. `--full` tracks every frame at the paper's budget.
"""
import sys
import time
from pathlib import Path

from ..core.tracking.settings import TrackingSettings
from .cmd_evaluate import evaluate
from .cmd_track import Progress, StepPrinter, open_subject, run_session

SAMPLE = Path(__file__).resolve().parents[1] / "sample_scenes"
DEMO_FRAMES = 30
DEMO_PARTICLES, DEMO_ITERATIONS = 100, 10


def add_arguments(p):
    p.add_argument("--scene-name", default="walk", help="sample scene folder (default: walk)")
    p.add_argument("--out", type=Path, default=Path("results/demo"), help="result folder (default: results/demo)")
    p.add_argument("--full", action="store_true", help="all frames at the paper's budget (200 x 15)")
    p.add_argument("--seed", type=int, default=0)


def run(args):
    from ..addon.scene_bridge import find_armature
    from .track_session import TrackSession

    capture = SAMPLE / args.scene_name
    if not (capture / "subject.blend").exists():
        print(f"markerless_mocap demo: the sample scene {capture} is missing; it ships with the repository "
              f"(regenerate it with sample_scenes/generate.py)", file=sys.stderr)
        return 2
    if args.full:
        settings = TrackingSettings(seed=args.seed)
        frames = None
        what = "all frames, 200 particles x 15 iterations (the paper's budget)"
    else:
        settings = TrackingSettings(seed=args.seed, particles=DEMO_PARTICLES, iterations=DEMO_ITERATIONS)
        frames = range(DEMO_FRAMES)
        what = (f"first {DEMO_FRAMES} frames, {DEMO_PARTICLES} particles x {DEMO_ITERATIONS} iterations "
                f"(a short demo; the paper's budget is 200 x 15: use --full)")
    print(f"Markerless Mocap demo: tracking sample scene '{args.scene_name}' with ISA ({settings.likelihood}: "
          f"learned person mask,\n  edges and learned keypoints) and the local ICP refinement;\n"
          f"  {what}.", file=sys.stderr)
    t0 = time.perf_counter()
    scene = open_subject(capture / "subject.blend")
    session = TrackSession(scene, find_armature(scene), capture, args.out, settings, frames=frames,
                           log=lambda m: print(m, file=sys.stderr), step=StepPrinter())
    run_session(session, Progress(session.n_total))
    written = session.finish()
    summary, plot = evaluate(args.out, capture / "gt_joints.npz")
    print(f"\nResult folder: {args.out.resolve()} ({', '.join(sorted(written))})")
    print(f"Tracked {summary.frames} frames in {time.perf_counter() - t0:.0f} s.")
    print(f"3D error over 15 joints vs ground truth: {summary.mean_mm:.1f} +- {summary.std_mm:.1f} mm "
          f"(max {summary.max_mm:.0f} mm, PCK@50mm {summary.pck50:.2f}); plot: {plot}")
    print(summary.json_line(scene=args.scene_name, demo=not args.full))
    return 0
