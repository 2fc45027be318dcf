"""One jailed worker process and its request/response channel."""

from __future__ import annotations

import os
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union
import resource

from scenario_bank.jail import bwrap, seccomp, wire, zygote
from scenario_bank.jail.errors import (
    JailCrashError,
    JailError,
    JailLimitError,
    JailProtocolError,
    JailUnavailableError,
)
from scenario_bank.jail.limits import JailLimits
from scenario_bank.jail.output import OutputTail, printable
from scenario_bank.jail.pids_cgroup import JAIL_TASKS, TaskCap, cap_tasks

__all__ = ["JailedProcess", "JailRemoteError", "jail_status", "require_jail", "discard_spares", "FIX"]

FIX = (
    "install bubblewrap (Debian/Ubuntu: `sudo apt-get install bubblewrap`; scripts/setup.sh does it when it "
    "can), allow unprivileged user namespaces (`sudo sysctl -w kernel.unprivileged_userns_clone=1`, and on "
    "Ubuntu 24.04 `kernel.apparmor_restrict_unprivileged_userns=0`) and install pyseccomp "
    "(`pip install pyseccomp`, needs libseccomp2). If you wrote or reviewed the script yourself, you can "
    "run it without the jail: trusted=True in Python, --trusted on the command line"
)

_STATUS: Dict[str, Tuple[bool, str]] = {}


def jail_status() -> Tuple[bool, str]:
    """``(True, "")`` when jailed workers can start here, else ``(False, why)``; checked once per process."""
    if "status" not in _STATUS:
        _STATUS["status"] = _probe()
    return _STATUS["status"]


def _probe() -> Tuple[bool, str]:
    if sys.platform != "linux":
        return False, f"the jail needs Linux namespaces; this is {sys.platform}"
    if bwrap.bwrap_path() is None:
        return False, "bubblewrap (bwrap) is not installed"
    hidden = bwrap.hidden_by_scratch()
    if hidden:
        return False, (f"{hidden} is under {bwrap.SCRATCH}, which the jail replaces with an empty folder of its own. "
                       f"To fix: put dv2s-gym and its virtual environment outside {bwrap.SCRATCH} (e.g. in your "
                       "home folder or /var/tmp)")
    try:
        seccomp.filter_bytes()
    except Exception as error:  # ImportError, missing libseccomp, ...
        return False, f"the seccomp filter cannot be built ({type(error).__name__}: {error})"
    fd = seccomp.filter_fd()
    try:
        argv = bwrap.command([sys.executable, "-s", "-c", "pass"], scratch_bytes=2**20, seccomp_fd=fd,
                             environment=bwrap.worker_environment())
        done = subprocess.run(argv, env={"PATH": "/usr/bin:/bin"}, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              pass_fds=(fd,), timeout=60, start_new_session=True)
    except (OSError, subprocess.TimeoutExpired) as error:
        return False, f"bubblewrap could not start ({error})"
    finally:
        os.close(fd)
    if done.returncode != 0:
        reason = done.stderr.decode("utf-8", "replace").strip().splitlines()[-1:] or ["no message"]
        return False, f"bubblewrap could not create the jail: {reason[0][:300]}"
    return True, ""


def require_jail(what: str = "this script") -> None:
    """Raise :class:`JailUnavailableError` (naming the fix) unless jailed workers can start."""
    ok, why = jail_status()
    if not ok:
        fix = "" if "To fix:" in why else f". To fix: {FIX}"
        raise JailUnavailableError(f"{what} is untrusted Scenic and runs only in the jail, which is not "
                                   f"available here: {why}{fix}.")


def _printable_strings(value: Any, depth: int = 0) -> Any:
    if isinstance(value, str):
        return printable(value)
    if depth > 8:
        return None
    if isinstance(value, dict):
        return {printable(str(k)): _printable_strings(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list):
        return [_printable_strings(v, depth + 1) for v in value]
    return value


class JailRemoteError(JailError):
    """The worker answered with an error: ``error_type`` is its class name (a string, nothing is imported)."""

    def __init__(self, error_type: str, message: str, details: Dict[str, Any], output: str = "") -> None:
        super().__init__(message, output)
        self.error_type = error_type
        self.details = details
        self.plain_message = message


class _BwrapWorker:
    """A worker bubblewrap started: its :class:`subprocess.Popen`, killed with its process group."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self._proc = proc

    @property
    def pid(self) -> int:
        return self._proc.pid

    def poll(self) -> Optional[int]:
        return self._proc.poll()

    def wait(self, timeout: Optional[float] = None) -> int:
        return self._proc.wait(timeout=timeout)

    def kill(self) -> None:
        """SIGKILL bubblewrap and everything in its jail (its session), and reap it."""
        bwrap.kill_session(self._proc)


_Worker = Union[_BwrapWorker, "zygote.ForkedWorker"]


class JailedProcess:
    """A Python module run in the jail, answering requests on a private channel.

    The worker is forked by the module's zygote (:mod:`.zygote`: the module's
    ``preload()`` already imported, then ``serve(IN_FD, OUT_FD, started)`` in
    fresh namespaces with the seccomp filter and ``limits``), or, where no zygote
    can run, with ``DV2S_JAIL_ZYGOTE=0`` or with ``args``, started as ``python -m
    module IN_FD OUT_FD *args`` in a bubblewrap of its own. Either way it reads
    messages (:mod:`.wire`) on ``IN_FD`` and answers each with ``{"ok": true,
    "value": ...}`` or ``{"ok": false, "error": {"type", "message", ...}}`` on
    ``OUT_FD``. Its stdout and stderr are captured (only the last
    ``limits.output_bytes`` kept) and shown with errors. :meth:`close` (also on
    garbage collection) kills it and everything it started.
    """

    def __init__(self, module: str, *, limits: Optional[JailLimits] = None, name: str = "jailed worker",
                 args: Sequence[str] = ()) -> None:
        require_jail(name)
        self.limits = limits or JailLimits.from_env()
        self.name = name
        self.module = module
        self._proc: Optional[_Worker] = None
        self._task_cap: Optional[TaskCap] = None
        self._closed = False
        self.forked = False
        """Whether the zygote forked this worker (else bubblewrap started it)."""
        if not args and zygote.enabled():
            self._fork()
        if self._proc is None:
            spare = _take_spare(module, self.limits, tuple(args))
            if spare is not None:
                self.__dict__.update({k: v for k, v in spare.__dict__.items() if k not in ("name",)})
                spare._proc = None  # this object owns the worker now
            else:
                self._spawn(args)
        try:
            self.hello = self._receive(self.limits.start_seconds, stage="start")
        except BaseException:
            self.kill()
            raise
        if not self.forked and _spares_wanted():
            _keep_spare(module, self.limits, tuple(args))

    @classmethod
    def _unstarted(cls, module: str, limits: JailLimits, args: Sequence[str]) -> "JailedProcess":
        worker = cls.__new__(cls)
        worker.limits, worker.name, worker.module = limits, "jailed worker", module
        worker._proc, worker._closed, worker.forked, worker._task_cap = None, False, False, None
        worker._spawn(args)
        return worker

    def _fork(self) -> None:
        """Get the worker from the module's zygote; leave ``_proc`` unset if it cannot give one."""
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        out_r, out_w = os.pipe()
        try:
            proc = zygote.fork_worker(self.module, self.limits, (to_child_r, from_child_w, out_w))
        except zygote.ZygoteError:
            for fd in (to_child_w, from_child_r, out_r):
                os.close(fd)
            return
        finally:
            for fd in (to_child_r, from_child_w, out_w):  # the worker holds its own copies
                os.close(fd)
        self.forked = True
        self._attach(proc, to_child_w, from_child_r, out_r)
        self._task_cap = cap_tasks(self.limits.processes)
        if self._task_cap is not None and proc.pid is not None:
            try:  # before the first request: the script's code has not run yet
                self._task_cap.add(proc.pid)
            except OSError:
                self._task_cap.remove()
                self._task_cap = None

    def _spawn(self, args: Sequence[str]) -> None:
        """Start the worker in a bubblewrap of its own."""
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        out_r, out_w = os.pipe()
        filter_fd = seccomp.filter_fd()
        self._task_cap = cap_tasks(self.limits.processes, JAIL_TASKS)
        argv = [sys.executable, "-s", "-m", self.module, str(to_child_r), str(from_child_w), *args]
        command = bwrap.command(argv, scratch_bytes=self.limits.scratch_bytes, seccomp_fd=filter_fd,
                                environment=bwrap.worker_environment())
        try:
            proc = subprocess.Popen(
                command, stdin=subprocess.DEVNULL, stdout=out_w, stderr=out_w,
                pass_fds=(to_child_r, from_child_w, filter_fd), start_new_session=True,
                preexec_fn=self._apply_limits, env={"PATH": "/usr/bin:/bin"},  # bwrap is PID 1 inside: /proc/1/environ
            )
        except OSError as error:
            for fd in (to_child_r, to_child_w, from_child_r, from_child_w, out_r, out_w, filter_fd):
                os.close(fd)
            raise JailUnavailableError(f"could not start the jail for {self.name}: {error}. To fix: {FIX}.") from None
        for fd in (to_child_r, from_child_w, out_w, filter_fd):
            os.close(fd)
        self._attach(_BwrapWorker(proc), to_child_w, from_child_r, out_r)

    def _attach(self, proc: "_Worker", to_child_w: int, from_child_r: int, out_r: int) -> None:
        self._proc = proc
        self._to_child = os.fdopen(to_child_w, "wb", buffering=0)
        self._from_child = from_child_r
        self._output = OutputTail(out_r, self.limits.output_bytes)
        self._started = time.monotonic()
        self.requests = 0

    def _apply_limits(self) -> None:  # between fork and exec of bwrap: inherited by the worker
        for which, soft, hard in self.limits.rlimits():
            try:
                resource.setrlimit(which, (soft, hard))
            except (ValueError, OSError):
                pass
        if self._task_cap is not None:
            try:
                self._task_cap.add_self()
            except OSError:
                pass  # RLIMIT_NPROC still applies to a worker not started by root

    # ------------------------------------------------------------------ requests
    def call(self, op: str, timeout: Optional[float] = None, **payload: Any) -> Any:
        """Send request ``op`` with ``payload``; return the worker's value or raise.

        Raises :class:`JailRemoteError` (the worker reported an error),
        :class:`JailLimitError` (a limit killed it), :class:`JailCrashError` (it
        died) or :class:`JailProtocolError` (it sent garbage); after anything but
        a :class:`JailRemoteError` the worker is gone.
        """
        if self._closed or self._proc is None:
            raise JailCrashError(f"{self.name} is closed")
        self.requests += 1
        try:
            wire.write_message(self._to_child, {"op": op, **payload})
        except (BrokenPipeError, OSError):
            raise self._death(op) from None
        return self._receive(self.limits.request_seconds if timeout is None else timeout, stage=op)

    def _receive(self, timeout: float, stage: str) -> Any:
        deadline = time.monotonic() + timeout
        try:
            message = self._read_message(deadline)
        except TimeoutError:
            self.kill()
            raise JailLimitError(f"{self.name} exceeded the {timeout:g} s wall-clock limit while {_doing(stage)}",
                                 "wall", stage, self._output_text()) from None
        except EOFError:
            raise self._death(stage) from None
        except JailProtocolError as error:
            self.kill()
            raise JailProtocolError(f"{self.name} sent an invalid message while {_doing(stage)}: {error}",
                                    self._output_text()) from None
        if not isinstance(message, dict) or not isinstance(message.get("ok"), bool):
            self.kill()
            raise JailProtocolError(f"{self.name} sent an answer that is not {{ok, value|error}}", self._output_text())
        if message["ok"]:
            return message.get("value")
        error = message.get("error")
        if not isinstance(error, dict):
            error = {}
        error = _printable_strings(error)  # the worker's words reach a terminal: no escape sequences in them
        error_type = str(error.get("type", "Error"))[:100]
        text = str(error.get("message", ""))[:4000]
        if error.get("limit") == "memory":
            raise JailLimitError(f"{self.name} exceeded the {self.limits.describe_memory()} memory limit while "
                                 f"{_doing(stage)}", "memory", stage, self._output_text())
        raise JailRemoteError(error_type, text, error, self._output_text())

    def _read_message(self, deadline: float) -> Any:
        prefix = self._read_exactly(wire.PREFIX.size, deadline)
        magic, header_size, count = wire.PREFIX.unpack(prefix)
        if magic != wire.MAGIC or count > wire.MAX_BUFFERS:
            raise JailProtocolError("not a message")
        if header_size > wire.MAX_HEADER_BYTES:
            raise JailProtocolError(f"message header of {header_size} bytes is over the "
                                    f"{wire.MAX_HEADER_BYTES}-byte limit (bulk data goes in arrays)")
        sizes = struct.unpack(f"<{count}Q", self._read_exactly(8 * count, deadline)) if count else ()
        total = header_size + sum(sizes)
        if total > self.limits.message_bytes:
            raise JailProtocolError(f"message of {total} bytes is over the {self.limits.message_bytes}-byte limit")
        header = self._read_exactly(header_size, deadline)
        buffers = [self._read_exactly(n, deadline) for n in sizes]
        return wire.decode(header, buffers)

    def _read_exactly(self, size: int, deadline: float) -> bytes:
        chunks: List[bytes] = []
        left = size
        while left:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError
            ready, _, _ = select.select([self._from_child], [], [], min(remaining, 1.0))
            if not ready:
                if self._proc is not None and self._proc.poll() is not None:
                    raise EOFError
                continue
            chunk = os.read(self._from_child, min(left, 1 << 20))
            if not chunk:
                raise EOFError
            chunks.append(chunk)
            left -= len(chunk)
        return b"".join(chunks)

    def _death(self, stage: str) -> JailError:
        code = None
        if self._proc is not None:
            try:
                code = self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
        self.kill()
        output = self._output_text()
        # SIGXCPU comes from the soft CPU limit; SIGKILL we did not send, from the hard one 2 s later
        if code in (-signal.SIGXCPU, 128 + signal.SIGXCPU, -signal.SIGKILL, 128 + signal.SIGKILL):
            return JailLimitError(f"{self.name} exceeded the {self.limits.cpu_seconds} s CPU-time limit while "
                                  f"{_doing(stage)}", "cpu", stage, output)
        if "MemoryError" in output or "Cannot allocate memory" in output or "std::bad_alloc" in output:
            return JailLimitError(f"{self.name} exceeded the {self.limits.describe_memory()} memory limit while "
                                  f"{_doing(stage)}", "memory", stage, output)
        if code == 128 + signal.SIGXFSZ or code == -signal.SIGXFSZ:
            return JailLimitError(f"{self.name} wrote a file over the {self.limits.file_bytes} byte limit while "
                                  f"{_doing(stage)}", "file", stage, output)
        return JailCrashError(f"{self.name} died while {_doing(stage)} (exit status {code})", output)

    def _output_text(self) -> str:
        self._output.join(0.2)
        return self._output.text().strip()

    @property
    def output(self) -> str:
        """The tail of what the worker printed (bounded by ``limits.output_bytes``)."""
        return self._output.text()

    @property
    def pid(self) -> Optional[int]:
        """The worker's process id on this machine (for a worker bubblewrap started: bubblewrap's)."""
        return None if self._proc is None else self._proc.pid

    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None and not self._closed

    # ------------------------------------------------------------------ cleanup
    def kill(self) -> None:
        """Kill the worker and everything in its jail (idempotent)."""
        proc = self._proc
        if proc is None:
            return
        proc.kill()
        self._closed = True
        if getattr(self, "_task_cap", None) is not None:
            self._task_cap.remove()
            self._task_cap = None
        for stream in (getattr(self, "_to_child", None),):
            try:
                if stream is not None:
                    stream.close()
            except OSError:
                pass
        fd = getattr(self, "_from_child", None)
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
            self._from_child = None

    def close(self) -> None:
        """Ask the worker to stop, then kill whatever is left."""
        if self._proc is not None and not self._closed and self._proc.poll() is None:
            try:
                wire.write_message(self._to_child, {"op": "exit"})
                self._proc.wait(timeout=2)
            except (OSError, subprocess.TimeoutExpired, ValueError):
                pass
        self.kill()

    def __del__(self) -> None:
        try:
            self.kill()
        except Exception:
            pass

    def __enter__(self) -> "JailedProcess":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# Without a zygote: one started, not yet used worker per module and limits, so the next jailed env skips
# the ~4 s of importing Scenic and highway-env. Started from the caller's thread (bubblewrap's --die-with-parent
# follows the thread that started it), only after a first jailed worker was asked for, never shared:
# each worker serves one owner and is never reused for another script.
_SPARES: Dict[Tuple[str, JailLimits, Tuple[str, ...]], JailedProcess] = {}


def _spares_wanted() -> bool:
    return os.environ.get("DV2S_JAIL_SPARE", "1") != "0" and threading.current_thread() is threading.main_thread()


def _take_spare(module: str, limits: JailLimits, args: Tuple[str, ...]) -> Optional[JailedProcess]:
    spare = _SPARES.pop((module, limits, args), None)
    if spare is not None and (spare._proc is None or spare._proc.poll() is not None):
        spare.kill()
        return None
    return spare


def _keep_spare(module: str, limits: JailLimits, args: Tuple[str, ...]) -> None:
    key = (module, limits, args)
    if key in _SPARES:
        return
    try:
        _SPARES[key] = JailedProcess._unstarted(module, limits, args)
    except JailError:
        pass


def discard_spares() -> None:
    """Kill the started, unused workers and stop the zygotes (tests call this to count processes)."""
    while _SPARES:
        _, spare = _SPARES.popitem()
        spare.kill()
    zygote.stop_zygotes()


def _doing(stage: str) -> str:
    return {"start": "starting", "open": "compiling the scenario", "compile": "compiling the scenario",
            "reset": "sampling and starting a scene", "step": "running a step", "render": "rendering",
            "verify": "checking the script", "trace": "sending the episode trace"}.get(stage, f"handling {stage!r}")
