"""Status lines that share the terminal with progress bars."""

from __future__ import annotations

import sys

__all__ = ["log_line"]


def log_line(line: str) -> None:
    """Print ``line`` to stderr on a line of its own: an open tqdm bar is cleared first and redrawn below it."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is not None and getattr(tqdm.tqdm, "_instances", None):
        tqdm.tqdm.write(line, file=sys.stderr)
    else:
        print(line, file=sys.stderr)
