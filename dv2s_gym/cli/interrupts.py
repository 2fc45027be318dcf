"""Ctrl-C while a command runs: noticed, and reported with what the command kept."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Optional

__all__ = ["SigintFlag", "report_interrupted"]

RESUME_NOTES = {
    "loop": "finished steps are kept in {out} (loop.json); rerun the same command to resume",
    "train": "rerun the same command with --resume to continue from the last checkpoint",
}
"""What an interrupted command kept, for commands whose own code does not say it more precisely."""


def _resume_note(args: argparse.Namespace) -> Optional[str]:
    note = RESUME_NOTES.get(args.command)
    return note.format(out=getattr(args, "out", None) or "the output folder") if note else None


def report_interrupted(args: argparse.Namespace, note: Optional[str] = None) -> int:
    """Print ``dv2s: interrupted`` with ``note`` (else the command's resume note); returns exit status 130."""
    note = note or _resume_note(args)
    print("dv2s: interrupted" + (f"; {note}" if note else ""), file=sys.stderr)
    return 130


class SigintFlag:
    """Notes whether Ctrl-C arrived while a command ran (the default handler still raises KeyboardInterrupt)."""

    def __init__(self) -> None:
        self.received = False
        self._previous = None

    def _handle(self, signum, frame) -> None:
        self.received = True
        signal.default_int_handler(signum, frame)

    def __enter__(self) -> "SigintFlag":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
