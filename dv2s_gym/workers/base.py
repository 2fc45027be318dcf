"""What every episode backend is: :class:`Backend` (the local process pool in :mod:`dv2s_gym.workers.pool`,
Ray in :mod:`dv2s_gym.workers.ray_pool`), the per-episode timeout and the default worker count."""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Iterable

__all__ = ["Backend", "OnResult", "default_workers", "DEFAULT_TIMEOUT"]

DEFAULT_TIMEOUT = 600.0
"""Seconds a worker may spend on one episode (scenario compilation included) before it counts as hung."""

OnResult = Callable[[Dict[str, Any]], None]
"""Called in the main process with each result as it arrives."""


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


class Backend:
    """Runs tasks and delivers their results as they finish.

    Subclasses implement :meth:`run`; :meth:`close` releases workers (also on ``with``).
    ``run`` may be called several times (the runner does so once per batch of a
    sequential run); workers stay up in between.
    """

    name = "backend"
    workers = 1
    streams = False
    """True when :meth:`run` takes ``more=`` (tasks added while it runs); :class:`LocalBackend` does."""

    def run(self, tasks: Iterable[Dict[str, Any]], on_result: OnResult) -> None:
        """Run every task; call ``on_result(result)`` in this process for each, as it finishes."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop the workers."""

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
