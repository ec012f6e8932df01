"""`python -m markerless_mocap ...`: the same command line as `blender --command markerless_mocap`."""
import sys

from .operators.cli import main

sys.exit(main(sys.argv[1:]))
