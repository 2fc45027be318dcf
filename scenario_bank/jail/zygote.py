"""The user's side of the jail's zygote: one fork server per worker module, and the workers it forks.

A jailed worker that imports Scenic, highway-env and matplotlib itself costs
seconds of CPU (4 s on an idle machine, 20 s on a loaded one). A zygote
(:mod:`.zygote_server`) imports them once in a jail of its own and forks each new
worker into fresh namespaces with its own limits, in milliseconds. The first
worker asked for starts the zygote, which tests the whole set-up once (the
probe); where that fails, or with ``DV2S_JAIL_ZYGOTE=0``,
:class:`~scenario_bank.jail.JailedProcess` starts each worker in a bubblewrap of
its own instead.

A zygote belongs to the process that started it (a forked copy of that process
starts its own) and dies with it; it is started from a thread that lives as long
as the process, since bubblewrap's ``--die-with-parent`` follows the thread that
started it.
"""

from __future__ import annotations

import concurrent.futures
import os
import queue
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple, TypeVar

from scenario_bank.jail import bwrap, linux
from scenario_bank.jail.limits import JailLimits
from scenario_bank.jail.output import OutputTail
from scenario_bank.jail.zygote_server import (
    CAPABILITIES,
    KILL,
    READY,
    REPLY,
    RUNNING,
    SPAWN,
    SPAWN_SECONDS,
    STATUS,
    pack_request,
    unpack_reply,
)
from scenario_bank.errors import DV2SError

__all__ = ["ZygoteError", "Zygote", "ForkedWorker", "enabled", "fork_worker", "stop_zygotes", "zygote_status"]

ANSWER_SECONDS = 30.0
"""How long the zygote may take to answer a kill or status request (it answers at once unless it is stuck)."""
UNKNOWN_STATUS = 255
"""A worker's exit status when its zygote is gone (bubblewrap's own "weird" status)."""
_SCRATCH_BYTES = 64 * 2**20  # the zygote's own /tmp: caches written while importing
_OUTPUT_BYTES = 16 * 1024

T = TypeVar("T")


class ZygoteError(DV2SError, RuntimeError):
    """A zygote could not start, or could not fork a worker; ``broken``: it is unusable and was stopped."""

    expected = False

    def __init__(self, message: str, broken: bool = True) -> None:
        super().__init__(message)
        self.broken = broken


# ---------------------------------------------------------------- the launcher thread
class _Launcher:
    """Runs jobs on a daemon thread that lives as long as the process."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self._jobs: "queue.SimpleQueue" = queue.SimpleQueue()
        threading.Thread(target=self._run, name="dv2s-jail-zygote-launcher", daemon=True).start()

    def _run(self) -> None:
        while True:
            job, done = self._jobs.get()
            try:
                done.set_result(job())
            except BaseException as error:
                done.set_exception(error)

    def run(self, job: Callable[[], T]) -> T:
        done: concurrent.futures.Future = concurrent.futures.Future()
        self._jobs.put((job, done))
        return done.result()


_LAUNCHER: Dict[str, _Launcher] = {}


def _launch(job: Callable[[], T]) -> T:
    launcher = _LAUNCHER.get("launcher")
    if launcher is None or launcher.pid != os.getpid():  # threads do not survive a fork
        launcher = _LAUNCHER["launcher"] = _Launcher()
    return launcher.run(job)


# ---------------------------------------------------------------- one zygote
class Zygote:
    """A started zygote for worker module ``module`` (blocks until it has imported what the module preloads)."""

    def __init__(self, module: str, start_seconds: float) -> None:
        self.module = module
        self.owner = os.getpid()
        self._lock = threading.RLock()
        self._socket: Optional[socket.socket] = None
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        out_read, out_write = os.pipe()
        argv = [sys.executable, "-s", "-m", "scenario_bank.jail.zygote_server", str(theirs.fileno()), module]
        command = bwrap.command(argv, scratch_bytes=_SCRATCH_BYTES, seccomp_fd=None,
                                environment=bwrap.worker_environment(), uid=0, capabilities=CAPABILITIES)
        try:
            self._proc = _launch(lambda: subprocess.Popen(
                command, stdin=subprocess.DEVNULL, stdout=out_write, stderr=out_write, pass_fds=(theirs.fileno(),),
                start_new_session=True, env={"PATH": "/usr/bin:/bin"}))
        except OSError as error:
            ours.close()
            os.close(out_read)
            raise ZygoteError(f"bubblewrap could not start: {error}") from None
        finally:
            theirs.close()
            os.close(out_write)
        self._socket = ours
        self._output = OutputTail(out_read, _OUTPUT_BYTES)
        with self._lock:
            _, value, _ = self._receive(READY, start_seconds)
        self.preload_seconds = value / 1000

    @property
    def pid(self) -> int:
        """The process id of the zygote's bubblewrap (its session and process group)."""
        return self._proc.pid

    def alive(self) -> bool:
        return self._socket is not None and self._proc.poll() is None

    # ------------------------------------------------------------ requests
    def spawn(self, limits: JailLimits, fds: Sequence[int]) -> "ForkedWorker":
        """Fork a worker on ``fds`` (requests in, answers out, output: the worker's ends, which stay open here)."""
        with self._lock:
            worker, _, pidfds = self._request(SPAWN, 0, limits, fds, SPAWN_SECONDS + ANSWER_SECONDS)
        if len(pidfds) != 1:
            for fd in pidfds:
                os.close(fd)
            self.stop()
            raise ZygoteError("the zygote answered a new worker without its pidfd")
        return ForkedWorker(self, worker, pidfds[0])

    def kill(self, worker: int) -> None:
        """SIGKILL ``worker`` and everything in its jail."""
        with self._lock:
            self._request(KILL, worker)

    def status(self, worker: int) -> Optional[int]:
        """``worker``'s exit status, or ``None`` while it runs."""
        with self._lock:
            _, value, _ = self._request(STATUS, worker)
        return None if value == RUNNING else value

    def _request(self, op: int, worker: int, limits: Optional[JailLimits] = None, fds: Sequence[int] = (),
                 timeout: float = ANSWER_SECONDS) -> Tuple[int, int, List[int]]:
        if self._socket is None:
            raise ZygoteError("the zygote was stopped")
        try:
            message = pack_request(op, worker, limits)
            socket.send_fds(self._socket, [message], list(fds)) if fds else self._socket.send(message)
        except OSError as error:
            self.stop()
            raise ZygoteError(f"the zygote is gone ({error}){self._said()}") from None
        return self._receive(op, timeout)

    def _receive(self, op: int, timeout: float) -> Tuple[int, int, List[int]]:
        """``(worker, value, fds)`` of the answer to ``op``; raises :class:`ZygoteError`."""
        assert self._socket is not None
        self._socket.settimeout(timeout)
        try:
            data, fds, _, _ = socket.recv_fds(self._socket, REPLY.size, 1)
        except OSError as error:  # TimeoutError included: a zygote that does not answer is stuck
            self.stop()
            reason = f"did not answer in {timeout:g} s" if isinstance(error, TimeoutError) else f"is gone ({error})"
            raise ZygoteError(f"the zygote {reason}{self._said()}") from None
        try:
            answered, error, worker, value, message = unpack_reply(data)
            if answered != op:
                raise ValueError(f"answer to request {answered}, not {op}")
        except ValueError as problem:
            for fd in fds:
                os.close(fd)
            self.stop()
            ended = "ended" if not data else f"sent a bad answer ({problem})"
            raise ZygoteError(f"the zygote {ended}{self._said()}") from None
        if error:
            for fd in fds:
                os.close(fd)
            broken = op == READY
            if broken:
                self.stop()
            raise ZygoteError(f"{os.strerror(error) if not message else message}", broken=broken)
        return worker, value, fds

    def _said(self) -> str:
        self._output.join(0.2)
        text = self._output.text().strip()
        return f"; it printed: {text[-2000:]}" if text else ""

    # ------------------------------------------------------------ cleanup
    def stop(self) -> None:
        """Kill the zygote and every worker it forked (idempotent)."""
        with self._lock:
            sock, self._socket = self._socket, None
            if sock is not None:
                sock.close()
        if os.getpid() != self.owner:
            return  # a forked copy of the user's process: the zygote is its parent's
        bwrap.kill_session(self._proc)


class ForkedWorker:
    """A worker a zygote forked, with the parts of :class:`subprocess.Popen` a jailed process uses."""

    def __init__(self, zygote: Zygote, worker: int, pidfd: int) -> None:
        self._zygote = zygote
        self._worker = worker
        self._pidfd: Optional[int] = pidfd
        self._owner = os.getpid()
        self.returncode: Optional[int] = None
        self.pid = linux.pidfd_pid(pidfd)
        """The worker's process id on this machine (``None`` if it is already gone)."""

    def _ended(self, timeout: float) -> bool:
        """Whether the worker (not its middle process) has ended, waiting up to ``timeout`` s."""
        if self._pidfd is None:
            return True
        return bool(select.select([self._pidfd], [], [], timeout)[0])

    def poll(self) -> Optional[int]:
        """The exit status once the worker has ended and been reaped, else ``None``."""
        if self.returncode is None and self._ended(0):
            try:
                self.returncode = self._zygote.status(self._worker)
            except ZygoteError:
                self.returncode = UNKNOWN_STATUS
        return self.returncode

    def wait(self, timeout: Optional[float] = None) -> int:
        """The exit status; raises :class:`subprocess.TimeoutExpired` after ``timeout`` s."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            remaining = 1.0 if deadline is None else deadline - time.monotonic()
            if remaining <= 0:
                raise subprocess.TimeoutExpired("jailed worker", timeout or 0)
            if self._ended(min(remaining, 1.0)):
                time.sleep(min(remaining, 0.005))  # ended: its middle process exits at once
        return self.returncode  # type: ignore[return-value]

    def kill(self) -> None:
        """SIGKILL the worker and everything in its jail, and wait until it has ended (idempotent)."""
        pidfd, self._pidfd = self._pidfd, None
        if pidfd is None:
            return
        try:
            if os.getpid() == self._owner:  # a forked copy of the user's process leaves its parent's workers alone
                try:
                    self._zygote.kill(self._worker)
                except ZygoteError:
                    pass  # a stuck zygote was stopped, and its workers with it
                select.select([pidfd], [], [], 10)
        finally:
            os.close(pidfd)
        if self.returncode is None:
            self.returncode = 128 + signal.SIGKILL


# ---------------------------------------------------------------- the zygotes of this process
_ZYGOTES: Dict[Tuple[int, str], Zygote] = {}
_REGISTRY = threading.Lock()
_PROBE: Dict[str, str] = {}  # "failed": why the zygote cannot work here (cached for the process)


def enabled() -> bool:
    """Whether new workers are forked by a zygote: not with ``DV2S_JAIL_ZYGOTE=0``, nor once one failed to start here."""
    return os.environ.get("DV2S_JAIL_ZYGOTE", "1") != "0" and "failed" not in _PROBE


def zygote_status() -> Tuple[bool, str]:
    """``(True, "")`` unless zygotes are turned off or failed to start here (``(False, why)``)."""
    if os.environ.get("DV2S_JAIL_ZYGOTE", "1") == "0":
        return False, "DV2S_JAIL_ZYGOTE=0"
    return ("failed" not in _PROBE), _PROBE.get("failed", "")


def _zygote(module: str, start_seconds: float) -> Zygote:
    key = (os.getpid(), module)
    with _REGISTRY:
        zygote = _ZYGOTES.get(key)
        if zygote is not None and zygote.alive():
            return zygote
        try:
            zygote = _ZYGOTES[key] = Zygote(module, start_seconds)
        except ZygoteError as error:
            _ZYGOTES.pop(key, None)
            _PROBE["failed"] = str(error)  # the probe: one failed start and workers get a bubblewrap each
            raise
        return zygote


def fork_worker(module: str, limits: JailLimits, fds: Sequence[int]) -> ForkedWorker:
    """A worker of ``module`` forked by its zygote (started on first use) on the pipe ends ``fds``.

    Raises :class:`ZygoteError` when the zygote cannot start or fork it; the caller then starts the
    worker with bubblewrap.
    """
    return _zygote(module, limits.start_seconds).spawn(limits, fds)


def stop_zygotes() -> None:
    """Stop this process's zygotes and every worker they forked (tests do, to count processes)."""
    with _REGISTRY:
        zygotes = [z for (pid, _), z in _ZYGOTES.items() if pid == os.getpid()]
        for key in [k for k in _ZYGOTES if k[0] == os.getpid()]:
            del _ZYGOTES[key]
    for zygote in zygotes:
        zygote.stop()
