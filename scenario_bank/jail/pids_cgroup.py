"""A cap on the tasks (processes and threads) of one jailed worker, by a pids cgroup.

``RLIMIT_NPROC`` does not hold for a worker started by root (its user is the machine's root
outside the jail, to which the limit does not apply), so where the machine lets this process
make a cgroup under its own pids cgroup, each worker gets one whose ``pids.max`` is its
``processes`` limit (plus bubblewrap's own processes when they join it). Where no such cgroup can be made
(no pids controller, no write access), :func:`cap_tasks` returns ``None`` and the rlimit is all
there is; ``DV2S_JAIL_PIDS_CGROUP=0`` turns the cgroup off.
"""

from __future__ import annotations

import atexit
import os
import uuid
from pathlib import Path
from typing import Optional, Set

__all__ = ["JAIL_TASKS", "TaskCap", "cap_tasks", "pids_cgroup_folder"]

JAIL_TASKS = 2
"""Tasks of a bubblewrap jail besides the worker's own: bubblewrap and its init in the PID namespace."""
_PREFIX = "dv2s-jail-"


def _own_pids_cgroup() -> Optional[Path]:
    """The folder of this process's pids cgroup (cgroup v1 pids hierarchy, or the v2 one), or ``None``."""
    try:
        with open("/proc/self/cgroup", encoding="ascii") as handle:
            memberships = [line.rstrip("\n").split(":", 2) for line in handle]
        with open("/proc/self/mountinfo", encoding="ascii") as handle:
            mounts = [line.split() for line in handle]
    except OSError:
        return None
    for fields in mounts:
        try:
            dash = fields.index("-")
            fstype, options, root, mount_point = fields[dash + 1], fields[dash + 3], fields[3], fields[4]
        except (ValueError, IndexError):
            continue
        for hierarchy in memberships:
            if len(hierarchy) != 3:
                continue
            v1 = fstype == "cgroup" and "pids" in options.split(",") and "pids" in hierarchy[1].split(",")
            v2 = fstype == "cgroup2" and hierarchy[0] == "0" and hierarchy[1] == ""
            if not (v1 or v2):
                continue
            relative = os.path.relpath(hierarchy[2], root) if hierarchy[2].startswith(root) else None
            if relative is None or relative.startswith(".."):
                continue
            folder = Path(mount_point) / relative
            if (folder / "cgroup.procs").exists():
                return folder.resolve()
    return None


def pids_cgroup_folder() -> Optional[Path]:
    """Where workers' cgroups are made, or ``None`` if switched off or not found."""
    if os.environ.get("DV2S_JAIL_PIDS_CGROUP", "1") == "0":
        return None
    return _own_pids_cgroup()


class TaskCap:
    """One worker's pids cgroup: :meth:`add` a process to it, :meth:`remove` it once the worker is gone."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def add(self, pid: int) -> None:
        """Move process ``pid`` (with all its threads; what it starts later follows) into the cgroup."""
        with open(self.path / "cgroup.procs", "w", encoding="ascii") as handle:
            handle.write(str(int(pid)))

    def add_self(self) -> None:
        """Move the calling process in (between fork and exec: the jail inherits it)."""
        self.add(os.getpid())

    def remove(self) -> None:
        """Remove the cgroup; while its processes are still exiting, a later cap (or the exit) retries."""
        try:
            self.path.rmdir()
        except OSError:
            _pending.add(self.path)


_pending: Set[Path] = set()


def _owner_gone(name: str) -> bool:
    try:
        os.kill(int(name[len(_PREFIX):].split("-", 1)[0]), 0)
    except (ValueError, ProcessLookupError):
        return True
    except PermissionError:
        return False
    return False


def _sweep(folder: Path) -> None:
    """Remove this process's emptied cgroups, and those of processes that died before removing theirs."""
    for path in list(_pending):
        try:
            path.rmdir()
            _pending.discard(path)
        except FileNotFoundError:
            _pending.discard(path)
        except OSError:
            pass
    try:
        for child in folder.iterdir():
            if child.name.startswith(_PREFIX) and _owner_gone(child.name):
                try:
                    child.rmdir()  # fails while a task is still in it
                except OSError:
                    pass
    except OSError:
        pass


def cap_tasks(limit: int, jail_tasks: int = 0) -> Optional[TaskCap]:
    """A new cgroup allowing ``limit`` tasks (the worker's threads, its main one included) plus
    ``jail_tasks`` (:data:`JAIL_TASKS` when the jail's own processes join too), or ``None`` where
    none can be made."""
    folder = pids_cgroup_folder()
    if folder is None:
        return None
    _sweep(folder)
    path = folder / f"{_PREFIX}{os.getpid()}-{uuid.uuid4().hex[:12]}"
    try:
        path.mkdir()
    except OSError:
        return None
    try:
        with open(path / "pids.max", "w", encoding="ascii") as handle:
            handle.write(str(max(1, int(limit)) + max(0, int(jail_tasks))))
    except OSError:
        TaskCap(path).remove()
        return None
    return TaskCap(path)


def _remove_pending() -> None:
    folder = pids_cgroup_folder()
    if folder is not None and _pending:
        _sweep(folder)


atexit.register(_remove_pending)
