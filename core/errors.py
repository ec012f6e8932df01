"""The one family of errors about the user's input.

`InputError` is the base of every error whose cause is something the user gave or chose: the capture
folder, the cameras' calibration, the footage, the rig, an actor file, a measured length, a setting, a
checkpoint to resume. Its message names what is wrong and the fix. The command line and the operators
report an InputError as the user's to fix (exit 2, an ERROR report in Blender) and any other exception
as a bug (operators/failures.py), so a bug never reads like a set-up mistake.

It derives from ValueError because callers (and tests) that predate it catch ValueError.
"""


class InputError(ValueError):
    """Something the user gave or chose cannot be used; the message names it and the fix."""


__all__ = ["InputError"]
