"""The worker backends by name: one table, read by :func:`get_backend`, by
``--backend`` of ``dv2s regress`` and ``dv2s mine``, and by the pytest plugin's ``--dv2s-backend``.

A backend is made by ``factory(*, workers, address, timeout) -> Backend`` (:class:`~dv2s_gym.workers.base.Backend`);
:func:`register_backend` adds one. The modules behind a backend are imported only when it is made, so reading
the names is cheap.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any, Callable, Dict, List, Optional, Sequence

from dv2s_gym.registered_names import RegisteredNames
from dv2s_gym.workers.errors import WorkerError
from scenario_bank.extras import missing_extra_message
from scenario_bank.named_registry import Registry

__all__ = ["BACKENDS", "BackendFactory", "register_backend", "registered_backends", "backend_factory", "backend_choices", "get_backend"]

BackendFactory = Callable[..., Any]
"""``factory(*, workers, address, timeout) -> Backend``."""


def _local(*, workers: Optional[int], address: Optional[str], timeout: Optional[float]):
    if address:
        raise WorkerError("--address is for --backend ray; the local backend runs on this machine")
    from dv2s_gym.workers.pool import LocalBackend

    return LocalBackend(workers, timeout=timeout)


def _ray(*, workers: Optional[int], address: Optional[str], timeout: Optional[float]):
    try:
        module = importlib.import_module("dv2s_gym.workers.ray_pool")
    except ModuleNotFoundError as error:
        if error.name not in ("dv2s_gym.workers.ray_pool", "ray"):
            raise
        if error.name == "ray":  # the optional dependency
            raise WorkerError(f"{missing_extra_message('ray', '--backend ray')}; or use --backend local") from None
        raise WorkerError("--backend ray needs dv2s_gym.workers.ray_pool, which is not installed; "
                          "install ray (pip install 'ray[default]') or use --backend local") from None
    options: Dict[str, Any] = {"workers": workers, "address": address}
    if timeout is not None and "timeout" in inspect.signature(module.RayBackend).parameters:
        options["timeout"] = timeout
    return module.RayBackend(**options)


def _unknown_backend(name: str, known: Sequence[str]) -> WorkerError:
    names = [repr(other) for other in known]
    choices = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"
    return WorkerError(f"unknown backend {name!r}: use {choices}")


_FACTORIES: Registry[BackendFactory] = Registry("worker backend", WorkerError, {"local": _local, "ray": _ray},
                                                unknown=_unknown_backend)

BACKENDS = tuple(_FACTORIES)
"""The backends that ship with dv2s-gym: a local process pool, or a Ray cluster."""


def register_backend(name: str, factory: BackendFactory, overwrite: bool = False) -> None:
    """Make ``get_backend(name, ...)`` (and ``--backend name``) call ``factory(workers=..., address=..., timeout=...)``,
    which returns a :class:`~dv2s_gym.workers.base.Backend`; a name registered already needs ``overwrite=True``."""
    _FACTORIES.register(name, factory, overwrite=overwrite)


def registered_backends() -> List[str]:
    """The worker backend names, the shipped ones first."""
    return list(_FACTORIES)


def backend_factory(name: str) -> BackendFactory:
    """The factory of the backend called ``name``; an unknown name is a :class:`WorkerError` naming the known ones."""
    return _FACTORIES.get(name)


def backend_choices() -> RegisteredNames:
    """The backend names as argparse ``choices``, read when the command line is parsed."""
    return RegisteredNames(registered_backends, BACKENDS)


def get_backend(name: str, workers: Optional[int] = None, address: Optional[str] = None,
                timeout: Optional[float] = None):
    """The backend called ``name``: ``"local"`` (process pool), ``"ray"`` (a Ray cluster at ``address``) or one
    added with :func:`register_backend`."""
    return backend_factory(name)(workers=workers, address=address, timeout=timeout)
