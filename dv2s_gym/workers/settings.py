"""Where a command's episodes run: :class:`WorkerSettings` (a backend, its workers, its address, a timeout)."""

from __future__ import annotations

import dataclasses
from typing import Optional

__all__ = ["WorkerSettings"]


@dataclasses.dataclass(frozen=True)
class WorkerSettings:
    """Where episodes run; none of it changes what a run records (a resumed run may use other workers).

    The pool that starts from them checks them (:func:`dv2s_gym.workers.backends.get_backend`), so a command reports
    a bad backend as its own error."""

    backend: str = "local"
    """``"local"`` (a process pool on this machine), ``"ray"`` (a Ray cluster at ``address``) or another name of
    :mod:`dv2s_gym.workers.backends`."""
    workers: Optional[int] = None
    """Worker processes (``None``: every core)."""
    address: Optional[str] = None
    """With ``backend="ray"``: the cluster's address (``None``: start or join a local one)."""
    timeout: Optional[float] = None
    """Seconds one episode may take before its worker counts as hung and is replaced (``None``: the pool's)."""
