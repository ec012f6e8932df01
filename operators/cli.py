"""Command line shared by `python -m markerless_mocap` and `blender --command markerless_mocap`.

Each sub-command lives in its own module (operators/cmd_<name>.py) exposing
`add_arguments(parser)` and `run(args) -> int`; this file only dispatches, importing the
module lazily so `--help` stays fast and one broken command cannot break the others. An exception a command
lets through ends it with the user's message (exit 2) or, for a bug, a message saying so (exit 70;
operators/failures.py).
"""
import argparse
import importlib
import sys

COMMANDS = {
    "demo": "track the bundled sample scene and print its error against the ground truth",
    "track": "track a capture with a rigged subject and write the result folder",
    "calibrate": "fit the actor's proportions (height, segment lengths) from the first frames; saves actor.json",
    "evaluate": "score a result folder: against ground-truth joints (3D error, PCK, plot) or, without them, against "
                "the learned evidence; contact sheet of the overlays",
    "compare": "run every optimiser on a capture at the same budget (the paper's Table 3)",
    "bench": "print speed figures of the likelihood engine (reference vs fast path)",
    "build": "build the installable extension zip with bundled wheels",
    "batch": "track many takes, each cut into chunks, on local processes or a Dask cluster; stitch and write each "
             "take's result folder",
    "track-chunk": "track one chunk of a take into its chunk folder (the unit of work of `batch`; no Blender UI)",
    "stitch": "stitch a take's finished chunks into its result folder",
    "plan-chunks": "print the chunks a take's frames are cut into (JSON with --json)",
    "seed-chunks": "follow a take's person by the landmarks alone, where its chunks after the first start",
}


def _command_module(name):
    return importlib.import_module(f"{__package__}.cmd_{name.replace('-', '_')}")


def build_parser():
    parser = argparse.ArgumentParser(
        prog="markerless_mocap",
        description="Markerless motion capture: fit a rigged character to calibrated multi-camera video.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, help_text in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        try:
            module = _command_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.endswith(f"cmd_{name.replace('-', '_')}"):
                p.set_defaults(_unavailable=name)
                continue
            raise
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if args.command is None:
        parser.print_help()
        return 2
    if getattr(args, "_unavailable", None):
        print(f"markerless_mocap: the '{args.command}' command is not part of this build yet", file=sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except Exception as exc:  # noqa: BLE001  (what a command did not report itself: the user's error or a bug)
        from .failures import cli_failure

        return cli_failure(args.command, exc)


def blender_command(argv):
    """Entry for `bpy.utils.register_cli_command`: Blender passes the arguments after the name."""
    return main(list(argv))
