"""The seam between the bank's checks and the simulator they run in.

Checking a script beyond its text (compile it, sample scenes, run a few seconds of
the episode) needs the simulator, which lives a layer up, in ``envs``. The bank
does not import it: the simulator layer names its jailed worker module here when
it is imported (``import envs`` calls :func:`use_simulator_worker` with
``"envs.jail_worker"``; so does ``import dv2s_gym``), and :mod:`scenario_bank.sandbox`
starts that module in the jail (:class:`scenario_bank.jail.JailedProcess`).

A worker module has ``preload()``, ``serve(IN_FD, OUT_FD, started)`` and a
``python -m`` entry, as :mod:`scenario_bank.jail.process` describes, and answers
the ``verify`` and ``check`` requests.
"""

from __future__ import annotations

from typing import Optional

from scenario_bank.errors import DV2SError, SettingError

__all__ = ["NoSimulatorError", "use_simulator_worker", "simulator_worker", "SCRATCH"]

SCRATCH = "/tmp/scenarios"
"""Where a worker writes the scripts it runs inside the jail (scenario ``i`` in ``SCRATCH/i/``): a path the user
never saw, which the host names back as the user named the script."""

_WORKER: Optional[str] = None


class NoSimulatorError(DV2SError):
    """A script check needs the simulator and no simulator layer has named its worker."""


def use_simulator_worker(module: str) -> None:
    """Name the jailed worker module (a dotted module name) that compiles, samples and runs scripts."""
    global _WORKER
    if not isinstance(module, str) or not module or not all(part.isidentifier() for part in module.split(".")):
        raise SettingError(f"the simulator worker is a dotted module name such as 'envs.jail_worker', not {module!r}")
    _WORKER = module


def simulator_worker() -> str:
    """The module :func:`use_simulator_worker` named; :class:`NoSimulatorError` when none was."""
    if _WORKER is None:
        raise NoSimulatorError(
            "checking a Scenic script runs it in the simulator, and no simulator is loaded: "
            "`import envs` (or `import dv2s_gym`) before adding to the bank or checking a script")
    return _WORKER
