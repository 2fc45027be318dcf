"""Where a command's episodes run: :class:`WorkerSettings` (a backend, its workers, its address, a timeout)."""

from __future__ import annotations

import dataclasses
from typing import Optional

from dv2s_gym.workers.backends import registered_backends
from dv2s_gym.workers.errors import WorkerError
from scenario_bank.field_checks import check_choice, check_int, check_number, check_text

__all__ = ["WorkerSettings"]


@dataclasses.dataclass(frozen=True)
class WorkerSettings:
    """Where episodes run; none of it changes what a run records (a resumed run may use other workers).

    Checked on construction (:class:`~dv2s_gym.workers.errors.WorkerError` naming the flag; the backend among those
    registered in :mod:`dv2s_gym.workers.backends`); ``workers=0`` is read as ``None`` (every core), as the loop and
    the miner always read it."""

    backend: str = "local"
    """``"local"`` (a process pool on this machine), ``"ray"`` (a Ray cluster at ``address``) or another name of
    :mod:`dv2s_gym.workers.backends`."""
    workers: Optional[int] = None
    """Worker processes (``None`` or 0: every core)."""
    address: Optional[str] = None
    """With ``backend="ray"``: the cluster's address (``None``: start or join a local one)."""
    timeout: Optional[float] = None
    """Seconds one episode may take before its worker counts as hung and is replaced (``None``: the pool's)."""

    def __post_init__(self) -> None:
        check_choice(WorkerError, "--backend", self.backend, registered_backends())
        if self.workers == 0 and not isinstance(self.workers, bool):
            object.__setattr__(self, "workers", None)
        check_int(WorkerError, "--workers", self.workers, low=1, optional=True, none_means="every core")
        check_text(WorkerError, "--address", self.address, optional=True, what="a Ray cluster address")
        check_number(WorkerError, "--timeout", self.timeout, low=0, interval="(]", optional=True)
