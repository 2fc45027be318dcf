"""The operating-system jail for untrusted Scenic.

A Scenic script is Python: every object it reaches leads back to the
interpreter, so an allowlist cannot make it safe. Scripts that do not ship with
the package are parsed, checked, compiled, sampled and simulated only in a
jailed worker process, and the user's process talks to it through a pipe that
carries data, never objects.

- :mod:`.bwrap`: the bubblewrap command line (user, mount, PID, IPC, network,
  UTS and cgroup namespaces; read-only file system but a private scratch
  folder; empty environment; dies with its parent).
- :mod:`.seccomp`: the system-call filter installed in the jail (no new
  processes, no ptrace, no namespaces, no sockets but ``AF_UNIX``, ...).
- :mod:`.limits`: CPU, memory, file-size, open-file and wall-clock limits.
- :mod:`.wire`: the data-only message format, validated on the way in.
- :mod:`.process`: :class:`JailedProcess`, one worker and its request/response
  channel, its captured (bounded) output and its kill.
- :mod:`.zygote` and :mod:`.zygote_server`: the fork server that imports the
  simulator once and forks each new worker into fresh namespaces in milliseconds
  (:mod:`.linux`: the system calls it needs; :mod:`.probe`: a worker for the
  jail's own tests).

This package imports nothing else of dv2s-gym, so every layer can use it.
"""

from scenario_bank.jail.errors import JailCrashError, JailError, JailLimitError, JailProtocolError, JailUnavailableError
from scenario_bank.jail.limits import JailLimits
from scenario_bank.jail.process import JailedProcess, jail_status, require_jail

__all__ = [
    "JailError",
    "JailUnavailableError",
    "JailLimitError",
    "JailCrashError",
    "JailProtocolError",
    "JailLimits",
    "JailedProcess",
    "jail_status",
    "require_jail",
]
