"""How many frames an actor calibration fits on (bpy-free, light: the command line's help quotes them)."""

MIN_FRAMES = 3       # frames with enough triangulated landmarks to fit proportions at all
DEFAULT_FRAMES = 20  # two thirds of a second at 30 fps. On the actor scene 10 frames left the upper arm 8 % long,
                     # 20 frames 2.5 %, 40 frames 2 % (docs/actor-calibration.md). A take shorter than this is
                     # tracked with the rig unless the calibration is asked for.
