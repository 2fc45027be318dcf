"""Errors the worker pools raise, each naming the problem and the fix."""

from __future__ import annotations

from envs.errors import DV2SError

__all__ = ["WorkerError"]


class WorkerError(DV2SError, ValueError):
    """Bad pool settings (backend, workers, timeout), a task of no registered kind, or workers that cannot start."""
