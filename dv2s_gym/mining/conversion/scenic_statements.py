"""A Scenic script read as statements: its top-level statements, and text split at top-level commas."""

from __future__ import annotations

import re
from typing import List, Optional

__all__ = ["top_statements", "split_top"]

_ONCE_OR_MORE = re.compile(r"^for\s+\w+\s+in\s+range\s*\(\s*([1-9]\d*)\s*\)\s*:\s*$")
"""A top-level loop over ``range(n)``, ``n`` >= 1: its body runs, so its statements are read as top-level ones."""


def top_statements(script: str) -> List[str]:
    """The script's top-level statements: a line at column 0 and the indented or bracketed lines that follow it,
    comments removed. The body of a top-level ``for _ in range(n)`` with ``n`` >= 1 (it runs) is read as top-level
    statements (:data:`_ONCE_OR_MORE`); a loop that may not run, or over anything else, is not."""
    statements: List[str] = []
    depth = 0
    in_doc = False
    loop_indent: Optional[int] = None  # the body's indentation of a top-level loop read as top-level statements
    for raw in script.splitlines():
        if raw.count('"""') % 2 == 1 or raw.count("'''") % 2 == 1:
            in_doc = not in_doc
            continue
        if in_doc:
            continue
        line = re.sub(r"#.*$", "", raw).rstrip()
        if not line.strip():
            continue
        if depth == 0 and _ONCE_OR_MORE.match(line):
            loop_indent = -1  # its body follows
            continue
        if loop_indent is not None and depth == 0:
            indent = len(line) - len(line.lstrip())
            if indent == 0:
                loop_indent = None
            else:
                if loop_indent < 0:
                    loop_indent = indent
                line = line[loop_indent:] if indent >= loop_indent else line.lstrip()
        elif loop_indent is not None and loop_indent > 0:
            line = line[loop_indent:] if line[:loop_indent].isspace() else line
        if depth == 0 and not line[0].isspace() and not (loop_indent is not None and statements
                                                            and statements[-1].endswith(",")):
            statements.append(line)  # (in a loop's body, a line after a trailing comma continues the statement)
        elif statements:
            statements[-1] += " " + line.strip()
        depth = max(0, depth + line.count("(") + line.count("[") - line.count(")") - line.count("]"))
    return statements


def split_top(text: str, sep: str = ",") -> List[str]:
    """``text`` split at ``sep`` outside brackets and strings."""
    parts, depth, quote, current = [], 0, None, []
    for char in text:
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == sep and depth == 0:
            parts.append("".join(current).strip())
            current = []
            continue
        current.append(char)
    if "".join(current).strip():
        parts.append("".join(current).strip())
    return parts
