"""Where a command's episodes run: :class:`WorkerSettings` (a backend, its workers, its address, a timeout)."""

from __future__ import annotations

import dataclasses
from typing import Any, Optional

from dv2s_gym.workers.errors import WorkerError

__all__ = ["BACKENDS", "WorkerSettings"]

BACKENDS = ("local", "ray")
"""The backends episodes can run on: a local process pool, or a Ray cluster."""


@dataclasses.dataclass(frozen=True)
class WorkerSettings:
    """Where episodes run; none of it changes what a run records (a resumed run may use other workers)."""

    backend: str = "local"
    """``"local"`` (a process pool on this machine) or ``"ray"`` (a Ray cluster at ``address``)."""
    workers: Optional[int] = None
    """Worker processes (``None``: every core)."""
    address: Optional[str] = None
    """With ``backend="ray"``: the cluster's address (``None``: start or join a local one)."""
    timeout: Optional[float] = None
    """Seconds one episode may take before its worker counts as hung and is replaced (``None``: the pool's)."""

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise WorkerError(f"unknown backend {self.backend!r}: use 'local' or 'ray' (--backend)")
        _check_positive("workers", self.workers, "--workers", int)
        _check_positive("timeout", self.timeout, "--timeout", (int, float))


def _check_positive(name: str, value: Any, flag: str, kinds: Any) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, kinds) or not value > 0:
        raise WorkerError(f"{name} ({flag}) must be a positive number or left out for the default, not {value!r}")
