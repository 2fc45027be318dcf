"""The bubblewrap command line of a jailed worker.

The worker sees a new, read-only root holding only what the interpreter needs:
``/usr`` (and the ``/bin``, ``/lib`` links), the dynamic linker's files in
``/etc``, the Python installation and virtual environment, and dv2s-gym's
``envs``, ``scenario_bank`` and ``policies`` packages. It gets a private
``/proc`` and ``/dev``, a size-limited tmpfs ``/tmp`` as its scratch folder
(its home and working directory), no network, no other processes, an empty
environment but the variables set here, no capabilities, and a new session
(no terminal to push input into). It dies with its parent (``--die-with-parent``)
and, as PID 1's child in its own PID namespace, takes everything it started
with it.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from scenario_bank.jail.errors import BwrapMissingError

__all__ = ["CODE_ROOT", "PACKAGES", "bwrap_path", "command", "worker_environment", "SCRATCH", "SCRATCH_DIRS",
           "SHM_BYTES", "WORKER_UID"]

CODE_ROOT = Path(__file__).resolve().parents[2]
"""The folder holding dv2s-gym's packages; the worker imports this code, not another copy."""
PACKAGES = ("envs", "scenario_bank", "policies")
"""The packages a worker may import (never ``dv2s_gym``: the front door has no business in the jail)."""
SCRATCH = "/tmp"
SCRATCH_DIRS = ("home", "tmp", "work")
"""The folders made in the scratch tmpfs; the worker starts in ``work``."""
SHM_BYTES = 2**20
"""Size of the jail's ``/dev/shm`` tmpfs."""
WORKER_UID = 65534
"""The worker's user and group id in the jail (nobody)."""
_ETC = ("ld.so.cache", "ld.so.conf", "ld.so.conf.d", "localtime", "alternatives", "fonts", "mime.types")


def bwrap_path() -> Optional[str]:
    """The ``bwrap`` executable (``DV2S_BWRAP`` overrides the search), or ``None``."""
    configured = os.environ.get("DV2S_BWRAP")
    if configured:
        return configured if os.access(configured, os.X_OK) else None
    return shutil.which("bwrap") or next((p for p in ("/usr/bin/bwrap", "/bin/bwrap") if os.access(p, os.X_OK)), None)


def worker_environment(extra: Optional[Dict[str, str]] = None) -> Dict[str, str]:
    """The whole environment of a worker: no variable of the user's (API keys stay out)."""
    env = {
        "PATH": "/usr/local/bin:/usr/bin:/bin",
        "HOME": f"{SCRATCH}/home",
        "TMPDIR": f"{SCRATCH}/tmp",
        "XDG_CACHE_HOME": f"{SCRATCH}/home/.cache",
        "PYTHONPATH": str(CODE_ROOT),
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONHASHSEED": "0",
        "PYTHONNOUSERSITE": "1",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "SDL_VIDEODRIVER": "offscreen",
        "SDL_AUDIODRIVER": "dummy",
        "PYGAME_HIDE_SUPPORT_PROMPT": "1",
        "MPLBACKEND": "Agg",
        "LANG": "C.UTF-8",
        "DV2S_IN_JAIL": "1",
    }
    env.update(extra or {})
    return env


def _python_roots() -> List[str]:
    roots = {os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix)}
    roots.add(os.path.dirname(os.path.dirname(os.path.realpath(sys.executable))))
    if sys.prefix != os.path.realpath(sys.prefix):
        roots.add(sys.prefix)  # the venv path as the interpreter sees it
    # A root under /usr is already bound with /usr; binding it again would only shadow nothing.
    return sorted(r for r in roots if not (r == "/usr" or r.startswith("/usr/")))


def hidden_by_scratch() -> Optional[str]:
    """The first folder the jail needs (the interpreter's, the code's) that lies under the jail's own
    :data:`SCRATCH` or ``/dev/shm``, which the jail mounts empty; ``None`` when there is none."""
    for folder in [*_python_roots(), str(CODE_ROOT)]:
        for covered in (SCRATCH, "/dev/shm"):
            if folder == covered or folder.startswith(covered.rstrip("/") + "/"):
                return folder
    return None


def _mounts() -> List[str]:
    args: List[str] = ["--ro-bind", "/usr", "/usr"]
    for link in ("bin", "sbin", "lib", "lib32", "lib64", "libx32"):
        host = Path("/") / link
        if host.is_symlink():
            args += ["--symlink", os.readlink(host), str(host)]
        elif host.is_dir():
            args += ["--ro-bind", str(host), str(host)]
    for name in _ETC:
        if os.path.exists(f"/etc/{name}"):
            args += ["--ro-bind", f"/etc/{name}", f"/etc/{name}"]
    for root in _python_roots():
        args += ["--ro-bind", root, root]
    for package in PACKAGES:
        folder = CODE_ROOT / package
        if folder.is_dir():
            args += ["--ro-bind", str(folder), str(folder)]
    return args


_KERNEL_SETTINGS = ("sys", "sysrq-trigger", "irq", "bus", "fs")
"""Parts of ``/proc`` that change the machine rather than the process: read-only in the jail."""


def _read_only_kernel_settings() -> List[str]:
    # bubblewrap's --proc leaves /proc/sys writable, and a jail started by root maps its user to
    # the machine's root, who may write there: cover each with a read-only bind of the same path.
    args: List[str] = []
    for name in _KERNEL_SETTINGS:
        args += ["--ro-bind-try", f"/proc/{name}", f"/proc/{name}"]
    return args


def command(argv: Sequence[str], *, scratch_bytes: int, seccomp_fd: Optional[int],
            environment: Dict[str, str], uid: int = WORKER_UID, capabilities: Sequence[str] = ()) -> List[str]:
    """The full ``bwrap ... -- argv`` command line.

    ``uid`` and ``capabilities`` (kept in the jail's own user namespace) are for the zygote, which
    starts as uid 0 with ``CAP_SYS_ADMIN`` and ``CAP_SETFCAP`` there, does what needs them and
    drops them before anything else runs (:mod:`.zygote_server`); a worker gets uid 65534 and none.
    """
    bwrap = bwrap_path()
    if bwrap is None:
        raise BwrapMissingError("bwrap")
    capability_args = [arg for cap in capabilities for arg in ("--cap-add", cap)]
    args = [
        bwrap,
        "--unshare-user", "--unshare-ipc", "--unshare-pid", "--unshare-net", "--unshare-uts",
        "--unshare-cgroup-try",
        "--uid", str(int(uid)), "--gid", str(int(uid)), "--hostname", "dv2s-jail",
        "--die-with-parent", "--new-session", "--cap-drop", "ALL", *capability_args, "--clearenv",
        *_mounts(),
        "--proc", "/proc",
        *_read_only_kernel_settings(),
        "--dev", "/dev",
        "--size", str(int(scratch_bytes)), "--tmpfs", SCRATCH,
        "--size", str(SHM_BYTES), "--tmpfs", "/dev/shm",
        *[arg for name in SCRATCH_DIRS for arg in ("--dir", f"{SCRATCH}/{name}")],
        "--chdir", f"{SCRATCH}/work",
        "--remount-ro", "/",
        "--remount-ro", "/dev",  # bwrap's /dev is a tmpfs of no set size; its device nodes still work
    ]
    for key, value in environment.items():
        args += ["--setenv", key, value]
    if seccomp_fd is not None:
        args += ["--seccomp", str(seccomp_fd)]
    return [*args, "--", *argv]


def kill_session(proc: "subprocess.Popen") -> None:
    """SIGKILL the bubblewrap ``proc`` and everything in its jail (its process group), then reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass
