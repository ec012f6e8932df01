"""`plan-chunks`: the chunks a take's frames are cut into (core/batch/plan.py), as `batch` and the Flamenco job
type cut them."""
import json
import sys

from ..core.batch.plan import DEFAULT_CHUNK_FRAMES, DEFAULT_OVERLAP, DEFAULT_WARMUP, plan_to_json
from .cmd_track import parse_frames


def add_chunk_arguments(p):
    p.add_argument("--chunk-frames", type=int, default=DEFAULT_CHUNK_FRAMES,
                   help=f"the most frames a chunk keeps (default {DEFAULT_CHUNK_FRAMES})")
    p.add_argument("--warmup", type=int, default=DEFAULT_WARMUP,
                   help=f"frames a chunk tracks before those it keeps, to settle (default {DEFAULT_WARMUP}; "
                        "docs/batch.md, 'Warm-up')")
    p.add_argument("--overlap", type=int, default=DEFAULT_OVERLAP,
                   help=f"frames two chunks are cross-faded over (default {DEFAULT_OVERLAP})")


def add_arguments(p):
    p.add_argument("--frames", required=True, help="the take's frames A-B, inclusive, from 0")
    add_chunk_arguments(p)
    p.add_argument("--json", action="store_true", help="print the plan as one JSON object")


def run(args):
    frames = parse_frames(args.frames)
    plan = plan_to_json(frames[0], frames[-1], args.chunk_frames, args.warmup, args.overlap)
    if args.json:
        print(json.dumps(plan))
        return 0
    for c in plan["chunks"]:
        print(f"chunk {c['index']}: tracks {c['track'][0]}-{c['track'][1]}, keeps {c['keep'][0]}-{c['keep'][1]}"
              + (f", the first {c['fade_in']} cross-faded with chunk {c['index'] - 1}" if c["fade_in"] else ""),
              file=sys.stdout)
    return 0
