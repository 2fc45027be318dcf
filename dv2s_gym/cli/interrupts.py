"""Ctrl-C while a command runs: noticed, and reported with what the command kept."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Optional

__all__ = ["SigintFlag", "report_interrupted", "episodes_kept_note", "close_progress_bars"]

RESUME_NOTES = {
    "loop": "finished steps are kept in {out} (loop.json), and so are the finished episodes and checkpoints of the "
            "step it stopped in; rerun the same command to resume",
    "train": "rerun the same command with --resume to continue from the last checkpoint",
}
"""What an interrupted command kept, for commands whose own code does not say it more precisely."""


def _resume_note(args: argparse.Namespace) -> Optional[str]:
    note = RESUME_NOTES.get(args.command)
    return note.format(out=getattr(args, "out", None) or "the output folder") if note else None


def episodes_kept_note(path: Path) -> str:
    """What an interrupted run of episodes kept in its record ``path`` (one JSON line per finished episode)."""
    try:
        with open(path, "rb") as records:
            count = sum(1 for line in records if line.strip())
    except OSError:
        count = 0
    if not count:
        return "no episode had finished, so nothing was kept; rerun the same command to start again"
    return f"{count} finished episode{'s are' if count != 1 else ' is'} kept in {path}; rerun the same command to resume"


def close_progress_bars() -> None:
    """Close the progress bars still open, so that what is printed next starts on a line of its own (and no
    bar is redrawn after it when the interpreter exits)."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is None:
        return
    for bar in list(getattr(tqdm.tqdm, "_instances", ())):
        try:
            bar.close()
        except Exception:  # a bar whose stream is gone cannot be closed more cleanly than this
            pass


def report_interrupted(args: argparse.Namespace, note: Optional[str] = None) -> int:
    """Print ``dv2s: interrupted`` with ``note`` (else the command's resume note) on a line of its own; returns
    exit status 130."""
    note = note or _resume_note(args)
    close_progress_bars()
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
