"""Resource limits of a jailed worker."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Optional
import math
import resource
from scenario_bank.errors import SettingError

__all__ = ["JailLimits", "START_CPU_SECONDS", "start_charging_cpu"]

_MIB = 2**20
_GIB = 2**30

# CPU time a worker may spend starting (interpreter, simulator imports) before its budget starts:
# a busy machine must not make a script's CPU limit fire in our own imports
START_CPU_SECONDS = 120


@dataclass(frozen=True)
class JailLimits:
    """Limits of one jailed worker process.

    A bank scenario needs about 0.8 GiB of address space and a few seconds of
    CPU to import, compile and run a 20-s episode; the defaults leave room for
    large OpenDRIVE maps and long training runs. Environment variables
    ``DV2S_JAIL_CPU`` (s), ``DV2S_JAIL_MEMORY_MB``, ``DV2S_JAIL_REQUEST_SECONDS`` and
    ``DV2S_JAIL_COMPILE_SECONDS`` override them (:meth:`from_env`); without the last, a set
    ``DV2S_JAIL_REQUEST_SECONDS`` limits compiling too.

    Attributes:
        cpu_seconds: CPU time of the worker's requests (``RLIMIT_CPU``, counted from the
            moment it has started; starting a worker that imports the simulator itself may
            take up to ``START_CPU_SECONDS`` more, one forked by the zygote starts at zero); a
            long-lived env worker (training) needs hours, a one-off check seconds.
        memory_bytes: address space (``RLIMIT_AS``).
        file_bytes: largest file the worker may write in its scratch folder (``RLIMIT_FSIZE``).
        scratch_bytes: size of the scratch file system (a tmpfs).
        open_files: ``RLIMIT_NOFILE``.
        processes: ``RLIMIT_NPROC`` (threads count; the seccomp filter refuses new processes anyway).
        start_seconds: wall-clock time to start the worker and import the simulator.
        request_seconds: wall-clock time of one request (reset, step, ...).
        compile_seconds: wall-clock time to compile the scripts (and load their maps) when an env opens.
        message_bytes: largest message the worker may send.
        output_bytes: how much of the worker's printed output is kept (the tail).
    """

    cpu_seconds: int = 6 * 3600
    memory_bytes: int = 4 * _GIB
    file_bytes: int = 64 * _MIB
    scratch_bytes: int = 256 * _MIB
    open_files: int = 256
    processes: int = 64
    start_seconds: float = 120.0
    request_seconds: float = 120.0
    compile_seconds: float = 300.0
    message_bytes: int = 256 * _MIB
    output_bytes: int = 16 * 1024

    @classmethod
    def from_env(cls, **overrides) -> "JailLimits":
        """The defaults, overridden by ``DV2S_JAIL_*`` variables, then by ``overrides``."""
        base = cls()
        values = {}
        try:
            if "DV2S_JAIL_CPU" in os.environ:
                values["cpu_seconds"] = int(os.environ["DV2S_JAIL_CPU"])
            if "DV2S_JAIL_MEMORY_MB" in os.environ:
                values["memory_bytes"] = int(float(os.environ["DV2S_JAIL_MEMORY_MB"]) * _MIB)
            if "DV2S_JAIL_REQUEST_SECONDS" in os.environ:
                values["request_seconds"] = float(os.environ["DV2S_JAIL_REQUEST_SECONDS"])
                values["compile_seconds"] = values["request_seconds"]
            if "DV2S_JAIL_COMPILE_SECONDS" in os.environ:
                values["compile_seconds"] = float(os.environ["DV2S_JAIL_COMPILE_SECONDS"])
        except ValueError as error:
            raise SettingError(f"bad DV2S_JAIL_* limit: {error}; give whole seconds and megabytes") from None
        values.update(overrides)
        return replace(base, **values)

    def describe_memory(self) -> str:
        """The memory limit for messages (``"4 GiB"``)."""
        value = self.memory_bytes / _GIB
        return f"{value:g} GiB" if value >= 1 else f"{self.memory_bytes / _MIB:g} MiB"

    def rlimits(self, start_cpu_seconds: int = START_CPU_SECONDS):
        """``(resource, soft, hard)`` triples to set in the worker before it starts.

        ``start_cpu_seconds`` is the CPU time allowed for starting, on top of the budget (lowered by
        :func:`start_charging_cpu` once started); 0 for a worker forked by the zygote, which starts
        with the simulator imported and its CPU time at zero.
        """
        cpu = max(1, int(self.cpu_seconds)) + start_cpu_seconds
        return [
            (resource.RLIMIT_CPU, cpu, cpu + 2),  # SIGXCPU at the soft limit, SIGKILL 2 s later
            (resource.RLIMIT_AS, self.memory_bytes, self.memory_bytes),
            (resource.RLIMIT_FSIZE, self.file_bytes, self.file_bytes),
            (resource.RLIMIT_NOFILE, self.open_files, self.open_files),
            (resource.RLIMIT_NPROC, self.processes, self.processes),
            (resource.RLIMIT_CORE, 0, 0),
            (resource.RLIMIT_MEMLOCK, 0, 0),
            (resource.RLIMIT_MSGQUEUE, 0, 0),
        ]

    def with_request_seconds(self, seconds: Optional[float]) -> "JailLimits":
        return self if seconds is None else replace(self, request_seconds=float(seconds))


def start_charging_cpu() -> None:
    """In the worker, once started: lower ``RLIMIT_CPU`` to the CPU used so far plus the budget.

    The budget is what :meth:`JailLimits.rlimits` set beyond ``START_CPU_SECONDS``; a worker can
    only lower its limits, so this cannot grant more than the parent allowed.
    """
    soft, hard = resource.getrlimit(resource.RLIMIT_CPU)
    if soft == resource.RLIM_INFINITY:
        return
    usage = resource.getrusage(resource.RUSAGE_SELF)
    used = int(math.ceil(usage.ru_utime + usage.ru_stime))
    budget = max(1, soft - START_CPU_SECONDS)
    new_soft = min(soft, used + budget)
    new_hard = min(hard, new_soft + 2) if hard != resource.RLIM_INFINITY else new_soft + 2
    resource.setrlimit(resource.RLIMIT_CPU, (new_soft, new_hard))
