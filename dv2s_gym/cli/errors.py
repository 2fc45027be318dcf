"""How an error reaches the user: one line on stderr, the traceback only with ``--debug``."""

from __future__ import annotations

import argparse
import sys
import traceback

from scenario_bank.errors import DV2SError
from scenario_bank.extras import EXTRA_OF_MODULE, extra_of, missing_extra_message

__all__ = ["UsageError", "EXTRA_OF_MODULE", "missing_extra", "error_line", "report_error"]


class UsageError(DV2SError, ValueError):
    """A command-line value that cannot be used; the message names it and the fix."""


def missing_extra(error: BaseException) -> str:
    """The extra to install when ``error`` is an optional dependency that is not installed, else ``""``."""
    if not isinstance(error, ModuleNotFoundError) or not error.name:
        return ""
    return extra_of(error.name)


def error_line(error: BaseException) -> str:
    """One line for the user: the project's errors say what is wrong and the fix; others get their type."""
    message = " ".join(str(error).split())
    if missing_extra(error):
        return missing_extra_message(error.name)
    if message and (isinstance(error, DV2SError) and error.expected or isinstance(error, ValueError)):
        return message
    if isinstance(error, OSError) and error.strerror:
        where = f": {error.filename}" if error.filename and str(error.filename) not in message else ""
        return f"{message}{where}"
    if isinstance(error, FileNotFoundError) and message:
        return message   # raised with a sentence of its own ("scenario file ... does not exist")
    return f"{type(error).__name__}: {message}" if message else type(error).__name__


def report_error(args: argparse.Namespace, error: BaseException, *, explained: bool) -> int:
    """Print ``error`` as ``dv2s: error: ...`` (with the traceback first under ``--debug``); returns exit status 2.

    ``explained``: the message says what is wrong and the fix; otherwise the line adds the ``--debug`` hint."""
    if args.debug:
        traceback.print_exc()
    hint = "" if explained or args.debug else " (an unexpected error: rerun with --debug for the traceback)"
    print(f"dv2s: error: {error_line(error)}{hint}", file=sys.stderr)
    return 2
