"""Reading this machine's process tree from /proc in tests (which processes a run left behind)."""

from __future__ import annotations

import os
from typing import List


def descendants(root: int) -> List[int]:
    """``root``'s descendants on this machine (in any PID namespace below ours)."""
    children = {}
    for pid in os.listdir("/proc"):
        try:
            with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
                children.setdefault(int(handle.read().rsplit(")", 1)[1].split()[1]), []).append(int(pid))
        except (OSError, ValueError, IndexError):
            pass
    found, todo = [], [root]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found
