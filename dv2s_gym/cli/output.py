"""How a command prints its result: JSON with ``--json``, else text safe for a terminal."""

from __future__ import annotations

import argparse
import json

__all__ = ["emit"]


def emit(args: argparse.Namespace, data, human: str) -> None:
    """Print ``data`` as JSON when ``--json`` was given, else the text ``human``."""
    from scenario_bank.jail.output import printable

    # bank text comes from folders and archives of others: no escape sequence reaches the terminal
    print(json.dumps(data, indent=2, default=str) if args.json else printable(human))
