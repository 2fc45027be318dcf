"""The zygote: a fork server in the jail, so that starting a jailed worker costs milliseconds.

Started by :mod:`.zygote` (the user's side) as ``python -s -m
scenario_bank.jail.zygote_server SOCKET_FD MODULE`` in the jail a worker gets
(:func:`.bwrap.command`: same mounts, namespaces and environment), but without
bubblewrap's seccomp filter, since it must fork. Starting, before it imports
anything of the simulator:

1. bubblewrap starts it as uid 0 of the jail's user namespace holding
   ``CAP_SYS_ADMIN`` and ``CAP_SETFCAP`` there (and nowhere else). It mounts a
   read-only procfs at ``/tmp/.proc``, which every worker's own ``/tmp`` hides:
   Linux lets a user namespace mount a procfs (as each worker does, to see only
   itself) only while its mount namespace holds one that no mount covers, and
   bubblewrap run by root covers parts of ``/proc`` with mounts that are locked
   in the workers' namespaces.
2. It moves into a user namespace of its own as uid 65534 (as bubblewrap does
   for a worker) and drops every capability.
3. It starts a throw-away worker through the whole set-up below, so that a
   kernel refusing any step is found at once (the user's side then starts
   workers with bubblewrap, one jail each).
4. It imports ``MODULE`` and calls ``MODULE.preload()`` (the simulator), builds
   the seccomp filter, becomes undumpable and tells the user's process it is ready.

It then answers fixed-size requests on its socket (``SPAWN``, ``KILL``,
``STATUS``) and nothing else: it never runs a script and reads nothing from a
worker but a fixed-size handshake sent before the worker's filter is installed.

A worker (``SPAWN``, which passes the worker's three pipe ends):

- the zygote forks a *middle* process, which keeps only those pipes, enters new
  user (uid 65534 mapped to the zygote's), mount, PID, IPC, network and UTS
  namespaces, makes its mounts private, mounts a fresh ``/tmp`` tmpfs of the
  worker's scratch size, an empty 1 MiB ``/dev/shm`` and its own ``/dev/pts``,
  and forks the worker;
- the worker, PID 1 of the new PID namespace, starts its own session, mounts a
  read-only procfs (it sees only itself), makes its scratch folders, becomes
  undumpable and bound to die with its parent, drops every capability, installs
  the filter of :mod:`.seccomp` (``no_new_privs``), sets its limits
  (:meth:`.JailLimits.rlimits`, CPU counted from zero) and runs
  ``MODULE.serve(3, 4, started)`` (requests in on fd 3, answers out on fd 4,
  output on fds 1 and 2);
- the middle process hands the zygote a pidfd of the worker, drops its
  capabilities, waits for the worker and exits with its status (128 + the signal when one killed it, as bubblewrap does).

``KILL`` sends SIGKILL through that pidfd: the worker is the init of its PID
namespace, so nothing in it survives. Being that init, the worker ignores
signals it has no handler for unless they come from outside its namespace, so
the soft CPU limit's SIGXCPU does nothing; the hard limit's SIGKILL, 2 s of CPU
later, ends it (exit status 137, which :class:`.JailedProcess` names as the CPU
limit). When the zygote ends (its socket closes),
bubblewrap's init ends and every worker with it.
"""

from __future__ import annotations

import errno
import importlib
import os
import resource
import select
import signal
import socket
import struct
import sys
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from scenario_bank.jail import linux, seccomp
from scenario_bank.jail.bwrap import SCRATCH, SCRATCH_DIRS, SHM_BYTES, WORKER_UID
from scenario_bank.jail.limits import JailLimits

__all__ = ["REQUEST", "REPLY", "READY", "SPAWN", "KILL", "STATUS", "RUNNING", "CAPABILITIES", "SPAWN_SECONDS",
           "pack_request", "unpack_reply", "main"]

REQUEST = struct.Struct("<4sIq6Q")
"""magic, op, worker id, then the limits of a new worker: CPU s, memory, file and scratch bytes, open files, processes."""
REPLY = struct.Struct("<4sIiqq256s")
"""magic, op, error (an errno, 0: done), worker id, value, message."""
_REQUEST_MAGIC = b"DVZq"
_REPLY_MAGIC = b"DVZa"
READY, SPAWN, KILL, STATUS = 1, 2, 3, 4
RUNNING = -1
"""``STATUS`` value of a worker still running."""
CAPABILITIES = ("CAP_SYS_ADMIN", "CAP_SETFCAP")
"""What bubblewrap leaves the zygote, in the jail's user namespace only, for steps 1 and 2."""
SPAWN_SECONDS = 60.0
"""How long a new worker may take to be set up (a fork and a few mounts; a loaded machine is slow)."""

_HANDSHAKE = struct.Struct("<iq256s")  # errno (0: done), pid, message
_HIDDEN_PROC = f"{SCRATCH}/.proc"
_IN_FD, _OUT_FD, _CHANNEL_FD = 3, 4, 5  # a worker's fds: 0 /dev/null, 1 and 2 output, 3 requests, 4 answers
_NAMESPACES = (linux.CLONE_NEWUSER | linux.CLONE_NEWNS | linux.CLONE_NEWPID | linux.CLONE_NEWIPC
               | linux.CLONE_NEWNET | linux.CLONE_NEWUTS)
_PROC_FLAGS = linux.MS_RDONLY | linux.MS_NOSUID | linux.MS_NODEV | linux.MS_NOEXEC

Serve = Callable[[int, int, float], int]


# ---------------------------------------------------------------- the protocol (the user's side uses it too)
def pack_request(op: int, worker: int = 0, limits: Optional[JailLimits] = None) -> bytes:
    """A request; ``limits`` for ``SPAWN``."""
    numbers = (0,) * 6 if limits is None else (
        limits.cpu_seconds, limits.memory_bytes, limits.file_bytes, limits.scratch_bytes, limits.open_files,
        limits.processes)
    return REQUEST.pack(_REQUEST_MAGIC, op, worker, *(max(0, int(n)) for n in numbers))


def _pack_reply(op: int, error: int = 0, worker: int = 0, value: int = 0, message: str = "") -> bytes:
    return REPLY.pack(_REPLY_MAGIC, op, error, worker, value, message.encode("utf-8", "replace")[:256])


def unpack_reply(data: bytes) -> Tuple[int, int, int, int, str]:
    """``(op, error, worker, value, message)``; raises ``ValueError`` on anything that is not a reply."""
    if len(data) != REPLY.size:
        raise ValueError(f"a reply of {len(data)} bytes")
    magic, op, error, worker, value, message = REPLY.unpack(data)
    if magic != _REPLY_MAGIC:
        raise ValueError("not a reply")
    return op, error, worker, value, message.rstrip(b"\0").decode("utf-8", "replace")


def _limits(numbers: Sequence[int]) -> JailLimits:
    cpu, memory, file, scratch, open_files, processes = numbers
    return JailLimits(cpu_seconds=max(1, cpu), memory_bytes=memory, file_bytes=file, scratch_bytes=max(2**20, scratch),
                      open_files=max(16, open_files), processes=max(1, processes))


def _describe(error: BaseException) -> Tuple[int, str]:
    code = error.errno if isinstance(error, OSError) and error.errno else errno.EIO
    return code, f"{type(error).__name__}: {error}"


def _exit_code(status: int) -> int:
    code = os.waitstatus_to_exitcode(status)
    return 128 - code if code < 0 else code  # killed by signal N: 128 + N


# ---------------------------------------------------------------- starting
def _leave_privileges() -> None:
    """Steps 1 and 2 of starting: the hidden procfs, then uid 65534 of a user namespace of our own, no capabilities."""
    os.mkdir(_HIDDEN_PROC, 0o700)
    linux.mount("proc", _HIDDEN_PROC, "proc", _PROC_FLAGS)
    linux.unshare(linux.CLONE_NEWUSER)
    linux.map_ids(WORKER_UID, 0)
    linux.drop_capabilities()


@dataclass
class _Worker:
    pidfd: Optional[int] = None
    code: Optional[int] = None  # the middle process's exit status, once reaped
    forgotten: bool = False  # killed: dropped as soon as reaped


class _Zygote:
    def __init__(self, host: socket.socket, syscall_filter: Any) -> None:
        self.host = host
        self.filter = syscall_filter
        self.serve_worker: Serve = lambda inbound, outbound, started: 0
        self.workers: Dict[int, _Worker] = {}

    # ------------------------------------------------------------ the zygote's loop
    def serve(self) -> int:
        """Answer the user's process until it closes its end."""
        wake_read, wake_write = os.pipe()
        os.set_blocking(wake_read, False)
        os.set_blocking(wake_write, False)
        signal.set_wakeup_fd(wake_write)
        signal.signal(signal.SIGCHLD, lambda *_: None)  # wakes select, so middle processes are reaped at once
        while True:
            ready, _, _ = select.select([self.host, wake_read], [], [])
            if wake_read in ready:
                while _read_some(wake_read):
                    pass
            self._reap()
            if self.host in ready:
                data, fds, _, _ = socket.recv_fds(self.host, REQUEST.size, 3)
                if not data:
                    return 0
                reply, reply_fds = self._answer(data, fds)
                try:
                    socket.send_fds(self.host, [reply], reply_fds) if reply_fds else self.host.send(reply)
                finally:
                    for fd in reply_fds:
                        os.close(fd)

    def _answer(self, data: bytes, fds: List[int]) -> Tuple[bytes, List[int]]:
        if len(data) != REQUEST.size or REQUEST.unpack(data)[0] != _REQUEST_MAGIC:
            _close(fds)
            return _pack_reply(0, errno.EINVAL, message="not a request"), []
        _, op, worker, *numbers = REQUEST.unpack(data)
        if op == SPAWN and len(fds) == 3:
            try:
                worker, pidfd = self.spawn(_limits(numbers), fds)
            except Exception as error:
                code, message = _describe(error)
                return _pack_reply(op, code, message=message), []
            return _pack_reply(op, worker=worker), [os.dup(pidfd)]
        _close(fds)
        if op == SPAWN:
            return _pack_reply(op, errno.EINVAL, message=f"a new worker needs 3 pipe ends, not {len(fds)}"), []
        if op == KILL:
            self.kill(worker)
            return _pack_reply(op, worker=worker), []
        if op == STATUS:
            entry = self.workers.get(worker)
            if entry is None:
                return _pack_reply(op, errno.ESRCH, worker, message="no such worker"), []
            return _pack_reply(op, worker=worker, value=RUNNING if entry.code is None else entry.code), []
        return _pack_reply(op, errno.EINVAL, message=f"unknown request {op}"), []

    def _reap(self) -> None:
        while True:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            entry = self.workers.get(pid)
            if entry is not None:
                entry.code = _exit_code(status)
                if entry.forgotten:
                    self._drop(pid)

    def _drop(self, pid: int) -> None:
        entry = self.workers.pop(pid)
        if entry.pidfd is not None:
            os.close(entry.pidfd)

    def kill(self, pid: int) -> None:
        """SIGKILL the worker (its PID namespace goes with it) and its middle process; forget both once reaped."""
        entry = self.workers.get(pid)
        if entry is None:
            return
        entry.forgotten = True
        if entry.pidfd is not None:
            try:
                signal.pidfd_send_signal(entry.pidfd, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if entry.code is None:
            os.kill(pid, signal.SIGKILL)  # our child, not yet reaped: the pid is still its own
        else:
            self._drop(pid)

    # ------------------------------------------------------------ a new worker
    def spawn(self, limits: JailLimits, fds: List[int]) -> Tuple[int, int]:
        """Fork a worker on the pipe ends ``fds`` (requests in, answers out, output); its id and pidfd."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            pid = os.fork()
        except OSError:
            _close(fds)
            ours.close()
            theirs.close()
            raise
        if pid == 0:
            self._run_middle(theirs, fds, limits, forget=(ours, self.host))  # never returns
        theirs.close()
        _close(fds)
        self.workers[pid] = entry = _Worker()
        try:
            _handshake(ours, entry)
        except BaseException:
            self.kill(pid)
            raise
        finally:
            ours.close()
        return pid, entry.pidfd

    def _run_middle(self, channel: socket.socket, fds: List[int], limits: JailLimits,
                    forget: Sequence[socket.socket]) -> None:
        """The middle process: new namespaces, then the worker; exits with the worker's status."""
        code = 127
        try:
            signal.set_wakeup_fd(-1)
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            self.workers.clear()
            for sock in forget:
                sock.detach()  # its fd is closed with all the others; the object must not close a reused number
            linux.prctl(linux.PR_SET_PDEATHSIG, signal.SIGKILL)
            channel = _keep_only(fds, channel)
            try:
                linux.prctl(linux.PR_SET_DUMPABLE, 1)  # our /proc/self/*_map must be ours to write
                _isolate(limits.scratch_bytes)
                linux.prctl(linux.PR_SET_DUMPABLE, 0)
                worker = os.fork()
            except BaseException as error:
                _send_handshake(channel, error)
                raise
            if worker == 0:
                self._run_worker(channel, limits)  # never returns
            pidfd = os.pidfd_open(worker)
            socket.send_fds(channel, [_HANDSHAKE.pack(0, worker, b"")], [pidfd])
            os.close(pidfd)
            channel.close()
            os.closerange(0, _CHANNEL_FD)  # the worker is the only holder of its pipes: its death closes them
            linux.drop_capabilities()  # it only waits now
            code = _exit_code(os.waitpid(worker, 0)[1])
        finally:
            os._exit(code)

    def _run_worker(self, channel: socket.socket, limits: JailLimits) -> None:
        """The worker: confine this process, say so on ``channel``, then serve the user's requests."""
        code = 1
        try:
            started = time.perf_counter()
            try:
                _confine(limits, self.filter)
            except BaseException as error:
                _send_handshake(channel, error)
                raise
            channel.send(_HANDSHAKE.pack(0, 0, b""))
            channel.close()
            code = self.serve_worker(_IN_FD, _OUT_FD, started)
        except SystemExit as exit_:
            code = 0 if exit_.code is None else exit_.code if isinstance(exit_.code, int) else 1
        except BaseException:
            traceback.print_exc()
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except Exception:
                    pass
            os._exit(code)

    def self_test(self) -> None:
        """Step 3 of starting: a worker set up and ended, or the error that stopped it."""
        fds = [os.open(os.devnull, os.O_RDWR) for _ in range(3)]
        pid, _ = self.spawn(JailLimits(), fds)
        status = os.waitpid(pid, 0)[1]
        self.workers[pid].forgotten = True
        self._drop(pid)
        if _exit_code(status) != 0:
            raise OSError(errno.EIO, f"the test worker exited with status {_exit_code(status)}")


def _handshake(ours: socket.socket, entry: _Worker) -> None:
    """Wait for the worker's pidfd (from the middle process) and its word that it is confined, in either order;
    raise the error that stopped either."""
    ours.settimeout(SPAWN_SECONDS)
    confined = False
    try:
        while entry.pidfd is None or not confined:
            data, fds, _, _ = socket.recv_fds(ours, _HANDSHAKE.size, 1)
            error, pid, message = _handshake_message(data)
            if error or len(fds) > 1 or (fds and pid <= 0):
                _close(fds)
                raise OSError(error or errno.EPROTO, message or "a new worker's middle process sent a bad handshake")
            if fds:
                entry.pidfd = fds[0]
            else:
                confined = True
    except TimeoutError:
        raise OSError(errno.ETIMEDOUT, f"a new worker was not set up in {SPAWN_SECONDS:g} s") from None


def _handshake_message(data: bytes) -> Tuple[int, int, str]:
    if len(data) != _HANDSHAKE.size:
        return errno.EPROTO, 0, "a new worker died while being set up"
    error, pid, message = _HANDSHAKE.unpack(data)
    return error, pid, message.rstrip(b"\0").decode("utf-8", "replace")


def _send_handshake(channel: socket.socket, error: BaseException) -> None:
    code, message = _describe(error)
    try:
        channel.send(_HANDSHAKE.pack(code, 0, message.encode("utf-8", "replace")[:256]))
    except OSError:
        pass


def _keep_only(fds: Sequence[int], channel: socket.socket) -> socket.socket:
    """Leave open only ``/dev/null`` as 0, the output as 1 and 2, the request and answer pipes as 3 and 4 and the
    handshake channel as 5; the channel as a socket on fd 5."""
    in_fd, out_fd, output_fd = fds
    sources = [os.open(os.devnull, os.O_RDONLY), output_fd, output_fd, in_fd, out_fd, channel.detach()]
    high = [os.dup(fd) for fd in sources]  # above every target number, so no target clobbers a source
    while min(high) <= _CHANNEL_FD:
        high = [os.dup(fd) for fd in high]
    for target, fd in enumerate(high):
        os.dup2(fd, target)
    os.closerange(_CHANNEL_FD + 1, os.sysconf("SC_OPEN_MAX"))
    return socket.socket(fileno=_CHANNEL_FD)


def _isolate(scratch_bytes: int) -> None:
    """In the middle process: the worker's namespaces and its own scratch, shared memory and terminals."""
    linux.unshare(_NAMESPACES)
    linux.map_ids(WORKER_UID, WORKER_UID)
    linux.mount("none", "/", None, linux.MS_REC | linux.MS_PRIVATE)
    linux.mount("tmpfs", SCRATCH, "tmpfs", linux.MS_NOSUID | linux.MS_NODEV, f"size={int(scratch_bytes)},mode=0755")
    linux.mount("tmpfs", "/dev/shm", "tmpfs", linux.MS_NOSUID | linux.MS_NODEV, f"size={SHM_BYTES},mode=0755")
    linux.mount("devpts", "/dev/pts", "devpts", linux.MS_NOSUID | linux.MS_NOEXEC, "newinstance,ptmxmode=0666,mode=620")


def _confine(limits: JailLimits, syscall_filter: Any) -> None:
    """In the worker (PID 1 of its namespace): its procfs and folders, then no way back, then its limits."""
    os.setsid()  # a group of its own: kill(0, ...) must not reach the zygote or its siblings
    linux.prctl(linux.PR_SET_PDEATHSIG, signal.SIGKILL)
    linux.mount("proc", "/proc", "proc", _PROC_FLAGS)
    for name in SCRATCH_DIRS:
        os.mkdir(f"{SCRATCH}/{name}", 0o755)
    os.chdir(f"{SCRATCH}/work")
    _fresh_random_state()
    linux.prctl(linux.PR_SET_DUMPABLE, 0)
    linux.drop_capabilities()
    syscall_filter.load()
    # last: set-up must not fail on a small address-space limit (the worker starts with the zygote's imports mapped)
    for which, soft, hard in limits.rlimits(start_cpu_seconds=0):
        resource.setrlimit(which, (soft, hard))


def _fresh_random_state() -> None:
    """Random state of its own, as a new process has: ``random`` reseeds itself after a fork, numpy does not."""
    numpy = sys.modules.get("numpy")
    if numpy is not None:
        numpy.random.seed()


def _read_some(fd: int) -> bytes:
    try:
        return os.read(fd, 4096)
    except BlockingIOError:
        return b""


def _close(fds: Sequence[int]) -> None:
    for fd in fds:
        try:
            os.close(fd)
        except OSError:
            pass


def main(argv: List[str]) -> int:
    """``zygote_server SOCKET_FD MODULE``: start (module docstring, steps 1-4), then serve."""
    host = socket.socket(fileno=int(argv[0]))
    try:
        _leave_privileges()
        zygote = _Zygote(host, seccomp.build_filter())
        zygote.self_test()
        started = time.perf_counter()
        module = importlib.import_module(argv[1])
        module.preload()
        zygote.serve_worker = module.serve
        linux.prctl(linux.PR_SET_DUMPABLE, 0)
        sys.stdout.flush()  # or every worker would print what the imports left in the buffers
        sys.stderr.flush()
    except Exception as error:
        code, message = _describe(error)
        host.send(_pack_reply(READY, code, message=message))
        return 1
    host.send(_pack_reply(READY, value=int((time.perf_counter() - started) * 1000)))
    return zygote.serve()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
