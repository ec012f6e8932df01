"""`calibrate`: fit the actor's proportions from the first frames of a capture and save OUT/actor.json."""
import sys
from pathlib import Path

from ..core.actor.measured_lengths import MEASURABLE
from .cmd_track import StepPrinter, add_tracking_options, open_subject, parse_frames, settings_from_args


def add_arguments(p):
    p.add_argument("--scene", type=Path,
                   help="SUBJECT.blend with the rig (not needed inside blender --background SUBJECT.blend)")
    p.add_argument("--capture", type=Path, required=True, help="capture folder")
    p.add_argument("--out", type=Path, required=True,
                   help="folder for actor.json (and calibration_frames/, the frames it tracked)")
    p.add_argument("--frames", help="capture frames A-B to calibrate on (default: the first 20)")
    p.add_argument("--armature", help="armature to use if the scene has several")
    p.add_argument("--asymmetric", action="store_true",
                   help="fit the left and right limbs separately (default: one length per segment for both sides)")
    p.add_argument("--landmarks-only", action="store_true",
                   help="fit to the learned landmarks alone (default: then refine the forearm and hip width against "
                        "the person masks of the same frames)")
    p.add_argument("--measured", action="append", metavar="SEGMENT=METRES",
                   help=f"a length measured on the actor, used in place of the footage's: one of "
                        f"{', '.join(MEASURABLE)} (repeat for several)")
    add_tracking_options(p)


def run(args):
    from ..addon.scene_bridge import find_armature
    from ..core.actor.measured_lengths import MeasuredLengthError, parse_measured
    from .actor_calibration import calibrate_actor, describe
    from .backend_choice import choose_backend
    from .failures import USER_ERRORS, cli_failure

    try:
        measured = parse_measured(args.measured)
    except MeasuredLengthError as exc:  # before anything is tracked
        print(f"markerless_mocap calibrate: {exc}", file=sys.stderr)
        return 2
    scene = open_subject(args.scene)
    try:
        backend = choose_backend(args.backend).used  # as track does: --backend gpu installs the GPU path
        armature = find_armature(scene, args.armature)
        fit, path = calibrate_actor(scene, armature, args.capture, args.out, settings_from_args(args, backend),
                                    frames=parse_frames(args.frames), log=lambda m: print(m, file=sys.stderr),
                                    step=StepPrinter(), symmetric=not args.asymmetric,
                                    silhouettes=not args.landmarks_only, measured=measured)
    except USER_ERRORS as exc:  # the capture, the rig, the frames, the backend, the folders: the message names the fix
        return cli_failure("calibrate", exc)
    for line in describe(fit):
        print(line)
    print(f"saved {path}; track later takes with --actor {path}", file=sys.stderr)
    return 0
