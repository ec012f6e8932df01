"""The user's errors against bugs, told apart the same way by the command line and the operators.

An InputError (core/errors.py) or an OSError (a file or folder the user named cannot be read or written) is the
user's to fix: its message alone, exit code EXIT_INPUT or an ERROR report in Blender. Any other exception is a
bug: a message that says so, the traceback logged, exit code EXIT_BUG. Blender's side never lets one escape an
operator, and the frames solved before it stay keyed and saved.
"""
import sys
import traceback

from ..core.errors import InputError

EXIT_INPUT = 2
EXIT_BUG = 70  # sysexits' EX_SOFTWARE: a script can tell a bug from a set-up mistake (2) and an interrupt (130)
EXIT_PARENT_GONE = 75  # sysexits' EX_TEMPFAIL: the batch worker that started the command is gone; run it again
USER_ERRORS = (InputError, OSError)


def is_user_error(exc):
    return isinstance(exc, USER_ERRORS)


def bug_message(exc, doing, traceback_at="the system console"):
    """What the user reads for a bug: that it is one, what it was, where its traceback is."""
    return (f"{doing} failed with an internal error ({type(exc).__name__}: {exc}). This is a bug in Markerless "
            f"Mocap, not a problem with your capture, rig or settings; the traceback is in {traceback_at}: "
            f"please report it")


def user_message(exc, doing):
    """The message for `exc` whichever it is; a bug's traceback is logged (Blender's console) as it is said."""
    if is_user_error(exc):
        return str(exc)
    traceback.print_exception(exc)
    return bug_message(exc, doing)


def cli_failure(command, exc, file=None):
    """Print the command line's message for `exc` (a bug: its traceback first); return the exit code."""
    file = file or sys.stderr
    if is_user_error(exc):
        print(f"markerless_mocap {command}: {exc}", file=file)
        return EXIT_INPUT
    traceback.print_exception(exc, file=file)
    print(f"markerless_mocap {command}: {bug_message(exc, command.capitalize(), 'the lines above')}", file=file)
    return EXIT_BUG
