"""The Linux calls the jail's zygote needs that Python 3.11 does not wrap: ``unshare``, ``mount``,
``prctl`` and ``capset`` (through the C library), and a pidfd's process id."""

from __future__ import annotations

import ctypes
import errno
import os
from typing import Optional

__all__ = ["unshare", "mount", "prctl", "map_ids", "drop_capabilities", "pidfd_pid", "CLONE_NEWNS", "CLONE_NEWUTS",
           "CLONE_NEWIPC", "CLONE_NEWUSER", "CLONE_NEWPID", "CLONE_NEWNET", "MS_RDONLY", "MS_NOSUID", "MS_NODEV",
           "MS_NOEXEC", "MS_REC", "MS_PRIVATE", "PR_SET_PDEATHSIG", "PR_SET_DUMPABLE"]

CLONE_NEWNS = 0x00020000
CLONE_NEWUTS = 0x04000000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
CLONE_NEWNET = 0x40000000

MS_RDONLY = 0x1
MS_NOSUID = 0x2
MS_NODEV = 0x4
MS_NOEXEC = 0x8
MS_REC = 0x4000
MS_PRIVATE = 0x40000

PR_SET_PDEATHSIG = 1
PR_SET_DUMPABLE = 4
PR_CAPBSET_DROP = 24
PR_CAP_AMBIENT = 47
PR_CAP_AMBIENT_CLEAR_ALL = 4
_CAPABILITY_VERSION_3 = 0x20080522
_LAST_POSSIBLE_CAP = 63

_LIBC: dict = {}


class _CapHeader(ctypes.Structure):
    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32)]


def _libc() -> ctypes.CDLL:
    if "libc" not in _LIBC:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.unshare.argtypes = [ctypes.c_int]
        libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]
        libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
        libc.capset.argtypes = [ctypes.POINTER(_CapHeader), ctypes.POINTER(_CapData)]
        _LIBC["libc"] = libc
    return _LIBC["libc"]


def _check(result: int, what: str) -> None:
    if result != 0:
        code = ctypes.get_errno()
        raise OSError(code, f"{what}: {os.strerror(code)}")


def unshare(flags: int) -> None:
    """``unshare(2)``: move this process into new namespaces (``CLONE_NEW*``)."""
    _check(_libc().unshare(flags), "unshare")


def mount(source: str, target: str, fstype: Optional[str], flags: int, data: Optional[str] = None) -> None:
    """``mount(2)``."""
    _check(_libc().mount(source.encode(), target.encode(), fstype.encode() if fstype else None, flags,
                         data.encode() if data is not None else None), f"mount {fstype or source} on {target}")


def prctl(option: int, arg: int = 0) -> None:
    """``prctl(2)`` with one argument."""
    _check(_libc().prctl(option, arg, 0, 0, 0), f"prctl({option})")


def map_ids(inside: int, outside: int) -> None:
    """Map uid and gid ``inside`` of this process's new user namespace to ``outside`` of its parent.

    Right after ``unshare(CLONE_NEWUSER)``: one id, our own, so no privilege in the parent is needed
    (supplementary groups are refused first, as the kernel requires of an unprivileged map).
    """
    for name, text in (("setgroups", "deny"), ("uid_map", f"{inside} {outside} 1"), ("gid_map", f"{inside} {outside} 1")):
        with open(f"/proc/self/{name}", "w", encoding="ascii") as handle:
            handle.write(text)


def drop_capabilities() -> None:
    """Drop every capability: the bounding and ambient sets, then the permitted, effective and inheritable ones."""
    libc = _libc()
    for cap in range(_LAST_POSSIBLE_CAP + 1):
        if libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0 and ctypes.get_errno() != errno.EINVAL:
            _check(-1, f"dropping capability {cap} from the bounding set")  # EINVAL: no such capability here
    _check(libc.prctl(PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0), "clearing the ambient capabilities")
    header = _CapHeader(_CAPABILITY_VERSION_3, 0)
    data = (_CapData * 2)()
    _check(libc.capset(ctypes.byref(header), data), "capset")


def pidfd_pid(pidfd: int) -> Optional[int]:
    """The process id (in this process's PID namespace) of the process ``pidfd`` refers to; ``None`` once it is gone."""
    try:
        with open(f"/proc/self/fdinfo/{pidfd}", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("Pid:"):
                    pid = int(line.split()[1])
                    return pid if pid > 0 else None
    except (OSError, ValueError, IndexError):
        pass
    return None
