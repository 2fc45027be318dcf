"""Rows of the mining run's append-only JSON-lines files, read back after a possible kill."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List

__all__ = ["read_rows"]


def read_rows(path: Path) -> List[Dict[str, Any]]:
    """The JSON objects of ``path``, one a line; none when it does not exist. A line that does not parse (the
    torn last line of a run killed mid-write) is left out: its work runs again."""
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            continue
    return rows
