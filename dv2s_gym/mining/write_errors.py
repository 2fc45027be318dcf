"""A mining run's own files that cannot be written (a full disk, a quota, a read-only file system).

Such a failure is not an episode's outcome: the run stops before recording the episode whose file could not be
written, and says which file, what is wrong and the fix; rerunning the same command resumes it and runs that
episode again.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Optional

from dv2s_gym.mining.errors import MiningError

__all__ = ["WRITE_ERRNOS", "is_write_failure", "write_failure", "run_write_error", "from_os_error"]

WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS)
"""The errors of writing a file that say nothing about the episode: the fix is on the machine's side."""


def is_write_failure(error: BaseException) -> bool:
    """Whether ``error`` is an ``OSError`` of :data:`WRITE_ERRNOS` (a full disk, a quota, a read-only file system)."""
    return isinstance(error, OSError) and error.errno in WRITE_ERRNOS


def write_failure(error: OSError, path: os.PathLike | str) -> dict:
    """What a worker reports instead of an episode when it could not write ``path`` (the failed episode's trace):
    ``{"path", "errno", "strerror"}``."""
    return {"path": str(path), "errno": error.errno,
            "strerror": error.strerror or (os.strerror(error.errno) if error.errno else str(error))}


def _file_system(path: Path) -> str:
    """The mount point holding ``path`` (its nearest existing folder when it does not exist)."""
    current = Path(os.path.abspath(path))
    while not current.exists() and current != current.parent:
        current = current.parent
    while not os.path.ismount(current) and current != current.parent:
        current = current.parent
    return str(current)


def run_write_error(path: Optional[os.PathLike | str], code: Optional[int], strerror: Optional[str] = None
                    ) -> MiningError:
    """The one-line error of a run file that could not be written: the file, the problem and the fix."""
    where = Path(path) if path else None
    fs = _file_system(where) if where is not None else "the run folder's file system"
    what = f"could not write {where}" if where is not None else "could not write a file of the run"
    if code == errno.EROFS:
        problem, fix = "the file system is read-only", f"make {fs} writable"
    elif code == errno.EDQUOT:
        problem, fix = "the disk quota is exceeded", f"free space within your quota on {fs}"
    elif code == errno.ENOSPC:
        problem, fix = "the disk is full", f"free space on {fs}"
    else:
        problem, fix = strerror or "the write failed", f"fix the problem with {fs}"
    return MiningError(f"{what}: {problem}; {fix} and rerun the same command to resume (finished episodes are "
                       "kept, this one runs again)")


def from_os_error(error: OSError) -> MiningError:
    """:func:`run_write_error` for an ``OSError`` raised while writing a run's file."""
    return run_write_error(error.filename, error.errno, error.strerror)
