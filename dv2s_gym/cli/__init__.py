"""The ``dv2s`` command: one CLI for the whole product.

Each command group is a module holding its subcommands' arguments (``add_parser``) next to the functions
that run them; :func:`build_parser` asks each to add its own, in the order ``dv2s --help`` lists them.

Before the command line is read, the plug-in modules named by the ``DV2S_PLUGINS`` environment variable
(comma-separated module names) are imported (:func:`scenario_bank.plugins.load_plugins_from_environment`): their
registrations (a failure type and its detector, a sampler, a backend) hold for the command and, through the
plug-in registries, in every worker process it starts.
"""

from __future__ import annotations

import argparse
import atexit
import os
import sys
from typing import List, Optional

from dv2s_gym.cli import (bank, convert, demo, evaluate, loop, maps, mine, regress, replay, run, train)
from dv2s_gym.cli.errors import UsageError, missing_extra, report_error
from dv2s_gym.cli.interrupts import SigintFlag, report_interrupted
from dv2s_gym.cli.parser import Parser
from scenario_bank.errors import DV2SError
from scenario_bank.plugins import PluginError, load_plugins_from_environment

__all__ = ["main", "build_parser"]

COMMAND_GROUPS = (demo, run, replay, maps, bank, convert, regress, mine, evaluate, train, loop)
"""The modules whose ``add_parser(subparsers)`` add the subcommands, in the order of ``dv2s --help``."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dv2s`` (every subcommand has ``--help``)."""
    parser = Parser(prog="dv2s", description="dv2s-gym: turn driving videos into Scenic "
                                    "scenarios and run them as Gymnasium episodes in highway-env.")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    parser.add_argument("--bank", default=None, help="bank folder of the commands that read a bank (default: the bank "
                        "shipped with dv2s-gym); also accepted after the command (and after `bank`'s subcommand)")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for group in COMMAND_GROUPS:
        group.add_parser(subparsers)
    parser.index_options()  # an option given to the wrong subcommand is named as the one of its command
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``dv2s`` console command.

    Exit status: 0 success, 1 a check failed (validation, generation; ``regress``: FAIL),
    2 an error (one line on stderr; ``--debug`` prints the traceback), 3 ``regress``
    INCONCLUSIVE, 4 ``regress`` ERROR (an episode ended in an error), 130 interrupted.

    Run as the command (``argv`` ``None``), an interrupted run exits at once once it has said so
    (:func:`_exit_at_once`); called with ``argv`` it returns the status like any other.
    """
    code = _main(argv)
    if code == 130 and argv is None:
        _exit_at_once(code)
    return code


def _exit_at_once(code: int) -> None:
    """Exit with ``code`` without the interpreter's teardown.

    The exit handlers still run (multiprocessing's stops the worker processes, so none is left behind) and the
    output is flushed; what is skipped is collecting every object of the run (a policy, its envs, DAgger's data),
    which kept an interrupted command alive for seconds, tens of seconds on a loaded machine, after it had
    said it was interrupted."""
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def _main(argv: Optional[List[str]]) -> int:
    try:
        load_plugins_from_environment()  # before parsing: a plug-in's sampler or backend is a choice of its flag
    except PluginError as error:
        given = sys.argv[1:] if argv is None else argv
        return report_error(argparse.Namespace(debug="--debug" in given), error, explained=True)
    parser = build_parser()
    args = parser.parse_args(argv)
    sigint = SigintFlag()
    try:
        with sigint:
            _refuse_unread_bank(parser, args)
            return int(args.func(args) or 0)
    except KeyboardInterrupt as stop:
        return report_interrupted(args, getattr(stop, "note", None))
    except BrokenPipeError:
        # the reader of our output went away (`dv2s bank list | head`): stop quietly, as Unix tools do
        _silence_stdout()
        return 141
    except DV2SError as error:  # the project's errors name the problem and the fix (a fault adds the --debug hint)
        return report_interrupted(args) if sigint.received else report_error(args, error, explained=error.expected)
    except Exception as error:  # any other error reaches the user as one line too, never a raw traceback
        if sigint.received:  # e.g. a broken pipe to a worker that Ctrl-C stopped first
            return report_interrupted(args)
        # OSError is expected: the operating system names the problem (a full disk, a permission, a file that went
        # away) and the file. A missing optional dependency names the extra to install. Anything else, a ValueError
        # included, is a fault of dv2s-gym or of a library (bad input is a DV2SError), so the --debug hint is added.
        return report_error(args, error, explained=isinstance(error, OSError) or bool(missing_extra(error)))


def _refuse_unread_bank(parser: Parser, args: argparse.Namespace) -> None:
    """A :class:`UsageError` for ``dv2s --bank DIR COMMAND`` when the command reads no bank (it never declared
    ``--bank`` with :func:`~dv2s_gym.cli.parser.bank_option`, which sets ``reads_bank``): the folder would be
    silently ignored, or the command would read the shipped bank instead."""
    if args.bank is None or getattr(args, "reads_bank", False):
        return
    readers = [name for name, command in parser.commands().items() if command.get_default("reads_bank")]
    raise UsageError(f"--bank {args.bank} names the scenario bank a command reads, and `dv2s {args.command}` reads "
                     f"none, so it would be ignored: drop --bank (the commands that read a bank and take it: "
                     f"{', '.join(readers)})")


def _silence_stdout() -> None:
    """Point stdout at /dev/null so Python's flush at exit does not fail again on the closed pipe."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
