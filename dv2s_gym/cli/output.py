"""How a command prints its result: JSON with ``--json``, else text safe for a terminal.

Every ``--json`` output is strict JSON (RFC 8259), which any parser reads: a number that is not finite (an
infinite minimum TTC when no vehicle was on a collision course, a NaN) is ``null``, never ``Infinity`` or ``NaN``.
"""

from __future__ import annotations

import argparse
import json
import math
import numbers
from typing import Any

from scenario_bank.jail.output import printable

__all__ = ["emit", "json_text", "strict_json_value"]


def strict_json_value(value: Any) -> Any:
    """``value`` with every number that is not finite (``inf``, ``-inf``, ``nan``) replaced by ``None``, in
    dicts, lists and tuples at any depth."""
    if isinstance(value, dict):
        return {key: strict_json_value(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json_value(item) for item in value]
    if isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral) and not math.isfinite(value):
        return None
    return value


def json_text(data: Any, *, indent: int = 2) -> str:
    """``data`` as strict JSON text: non-finite numbers are ``null``; values JSON has no type for are strings."""
    return json.dumps(strict_json_value(data), indent=indent, default=str, allow_nan=False)


def emit(args: argparse.Namespace, data, human: str) -> None:
    """Print ``data`` as strict JSON (:func:`json_text`) when ``--json`` was given, else the text ``human``."""
    # bank text comes from folders and archives of others: no escape sequence reaches the terminal
    print(json_text(data) if args.json else printable(human))
