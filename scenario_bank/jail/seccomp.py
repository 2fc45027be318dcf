"""The system-call filter of the jail, compiled by libseccomp (``pyseccomp``).

Installed by bubblewrap (``--seccomp FD``) just before the worker's interpreter
starts, or, in a worker forked by the zygote (:mod:`.zygote_server`), loaded by the
worker itself (:meth:`pyseccomp.SyscallFilter.load`, with ``no_new_privs``) before it
reads its first request. Like the filters of Flatpak and Chromium's renderer it allows by default
and refuses what a simulation never needs and an escape always does:

- new processes: ``fork``, ``vfork``, ``clone`` without ``CLONE_THREAD``; ``clone3``
  answers ``ENOSYS`` so that the C library falls back to ``clone`` for threads;
- other processes' memory and tracing: ``ptrace``, ``process_vm_readv/writev``;
- namespaces, mounts and the kernel: ``unshare``, ``setns``, ``mount``, ``pivot_root``,
  ``chroot``, module loading, ``kexec``, ``bpf``, ``perf_event_open``, keyrings,
  ``userfaultfd``, ``io_uring``, file handles, ``acct``, ``swapon``, ``reboot``, ...;
- the network: ``socket`` for any family but ``AF_UNIX`` (the network namespace is
  empty anyway);
- the terminal: ``ioctl(TIOCSTI)`` (pushing input into the user's shell).

A refused call fails with ``EPERM``; nothing is killed, so the worker reports the
error as the script's.
"""

from __future__ import annotations

import errno
import os
import socket
import tempfile

__all__ = ["DENIED_SYSCALLS", "build_filter", "filter_bytes", "filter_fd"]

DENIED_SYSCALLS = (
    "fork", "vfork", "ptrace", "process_vm_readv", "process_vm_writev", "unshare", "setns", "mount",
    "umount2", "pivot_root", "chroot", "init_module", "finit_module", "delete_module", "kexec_load",
    "kexec_file_load", "bpf", "perf_event_open", "keyctl", "add_key", "request_key", "userfaultfd",
    "io_uring_setup", "io_uring_enter", "io_uring_register", "open_by_handle_at", "name_to_handle_at",
    "acct", "swapon", "swapoff", "reboot", "syslog", "iopl", "ioperm", "quotactl", "settimeofday",
    "clock_settime", "adjtimex", "clock_adjtime", "mknod", "mknodat", "personality", "lookup_dcookie",
    "fanotify_init", "move_mount", "open_tree", "fsopen", "fsmount", "fsconfig", "fspick", "pidfd_getfd",
    "kcmp", "vhangup", "uselib", "nfsservctl", "migrate_pages", "move_pages", "mbind", "set_mempolicy",
    # anonymous files live in memory the address-space limit does not count
    "memfd_create", "memfd_secret",
)
_CLONE_THREAD = 0x00010000
_TIOCSTI = 0x5412

_CACHE: dict = {}


def build_filter():
    """The filter as a :class:`pyseccomp.SyscallFilter` (``load()`` installs it in this process, ``no_new_privs`` on)."""
    import pyseccomp as sc

    f = sc.SyscallFilter(defaction=sc.ALLOW)
    deny = sc.ERRNO(errno.EPERM)
    for name in DENIED_SYSCALLS:
        try:
            f.add_rule(deny, name)
        except (ValueError, RuntimeError, OSError):
            pass  # a call this kernel/architecture does not have
    f.add_rule(deny, "clone", sc.Arg(0, sc.MASKED_EQ, _CLONE_THREAD, 0))
    f.add_rule(sc.ERRNO(errno.ENOSYS), "clone3")
    f.add_rule(deny, "socket", sc.Arg(0, sc.NE, socket.AF_UNIX))
    f.add_rule(deny, "ioctl", sc.Arg(1, sc.MASKED_EQ, 0xFFFFFFFF, _TIOCSTI))
    return f


def filter_bytes() -> bytes:
    """The BPF program (cached per process)."""
    if "bpf" not in _CACHE:
        with tempfile.TemporaryFile() as handle:
            build_filter().export_bpf(handle)
            handle.seek(0)
            _CACHE["bpf"] = handle.read()
    return _CACHE["bpf"]


def filter_fd() -> int:
    """A readable file descriptor holding the filter, for ``bwrap --seccomp FD`` (caller closes it)."""
    data = filter_bytes()
    read, write = os.pipe()
    try:
        os.write(write, data)  # a few hundred bytes: fits the pipe buffer
    finally:
        os.close(write)
    return read
