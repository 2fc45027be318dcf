"""Where regression episodes run: a pool of local processes, or Ray.

A :class:`Backend` takes task dicts (see :mod:`dv2s_gym.regress.worker`) and hands each
result to a callback as soon as it finishes. :class:`LocalBackend` runs one process per
worker (``spawn`` context, ``OMP_NUM_THREADS=1``), each calling
:func:`~dv2s_gym.regress.worker.run_task` and keeping its envs and policies between
tasks. A worker that dies mid-episode (segfault, ``os._exit``, out of memory) or gives no
result within the per-episode timeout is killed and replaced; its task is retried once
(``retries``), then reported as an error result ``{"error": ..., "id", "role", ...}`` -
never silently dropped.

:func:`get_backend` picks one by name (``"local"`` or ``"ray"``; the Ray backend lives in
:mod:`dv2s_gym.regress.ray_backend`).
"""

from __future__ import annotations

import importlib
import inspect
import multiprocessing
import os
import time
from collections import deque
from multiprocessing.connection import wait
from typing import Any, Callable, Deque, Dict, Iterable, List, Optional, Tuple

from dv2s_gym.regress.errors import RegressError

__all__ = ["Backend", "LocalBackend", "get_backend", "default_workers", "DEFAULT_TIMEOUT"]

DEFAULT_TIMEOUT = 600.0
"""Seconds a worker may spend on one episode (scenario compilation included) before it counts as hung."""

OnResult = Callable[[Dict[str, Any]], None]


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


class Backend:
    """Runs tasks and delivers their results as they finish.

    Subclasses implement :meth:`run`; :meth:`close` releases workers (also on ``with``).
    ``run`` may be called several times (the runner does so once per batch of a
    sequential run); workers stay up in between.
    """

    name = "backend"
    workers = 1

    def run(self, tasks: Iterable[Dict[str, Any]], on_result: OnResult) -> None:
        """Run every task; call ``on_result(result)`` in this process for each, as it finishes."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop the workers."""

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _worker_main(connection) -> None:
    """A pool process: receive ``(index, task)``, send ``(index, result)``; ``None`` stops it."""
    os.environ["OMP_NUM_THREADS"] = "1"
    from dv2s_gym.regress.worker import error_result, run_task

    while True:
        try:
            message = connection.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if message is None:
            return
        index, task = message
        try:
            result = run_task(task)
        except BaseException as error:  # run_task reports episode errors itself; this is the last net
            result = error_result(task, f"{type(error).__name__}: {error}")
        try:
            connection.send((index, result))
        except (OSError, KeyboardInterrupt):
            return


class _Worker:
    def __init__(self, context) -> None:
        parent, child = context.Pipe()
        self.connection = parent
        self.process = context.Process(target=_worker_main, args=(child,), daemon=True,
                                       name="dv2s-regress-worker")
        saved = os.environ.get("OMP_NUM_THREADS")
        os.environ["OMP_NUM_THREADS"] = "1"  # set before the child imports numpy
        try:
            self.process.start()
        finally:
            if saved is None:
                os.environ.pop("OMP_NUM_THREADS", None)
            else:
                os.environ["OMP_NUM_THREADS"] = saved
        child.close()
        self.busy: Optional[Tuple[int, float]] = None  # (task index, start time)

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.connection.close()

    def stop(self) -> None:
        try:
            self.connection.send(None)
        except OSError:
            pass
        self.process.join(5)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(5)
        self.connection.close()


class LocalBackend(Backend):
    """A pool of local worker processes.

    Args:
        workers: processes (default: every core this process may use).
        timeout: seconds one episode may take before its worker counts as hung and is
            killed (default :data:`DEFAULT_TIMEOUT`; the first episode of a scenario in a
            worker includes compiling it).
        retries: how often a task whose worker crashed or hung is run again before it is
            reported as an error (default 1).
        start_method: ``"spawn"`` (default) or ``"forkserver"``.
    """

    name = "local"

    def __init__(self, workers: Optional[int] = None, timeout: Optional[float] = None, retries: int = 1,
                 start_method: str = "spawn") -> None:
        if workers is not None and int(workers) < 1:
            raise RegressError(f"--workers must be at least 1, not {workers}")
        if timeout is not None and not float(timeout) > 0:
            raise RegressError(f"the per-episode timeout must be positive, not {timeout}")
        if start_method not in ("spawn", "forkserver"):
            raise RegressError(f"start_method must be 'spawn' or 'forkserver', not {start_method!r}")
        self.workers = int(workers) if workers is not None else default_workers()
        self.timeout = float(timeout) if timeout is not None else DEFAULT_TIMEOUT
        self.retries = int(retries)
        self._context = multiprocessing.get_context(start_method)
        self._pool: List[_Worker] = []

    def _ensure(self, count: int) -> None:
        self._pool = [w for w in self._pool if w.process.is_alive()]
        while len(self._pool) < count:
            self._pool.append(_Worker(self._context))

    def run(self, tasks: Iterable[Dict[str, Any]], on_result: OnResult) -> None:
        from dv2s_gym.regress.worker import error_result

        tasks = list(tasks)
        if not tasks:
            return
        queue: Deque[int] = deque(range(len(tasks)))
        attempts: Dict[int, int] = {}
        failures: Dict[int, List[str]] = {}
        remaining = len(tasks)
        self._ensure(min(self.workers, len(tasks)))
        try:
            while remaining:
                for worker in self._pool:
                    if worker.busy is None and queue:
                        index = queue.popleft()
                        attempts[index] = attempts.get(index, 0) + 1
                        worker.busy = (index, time.monotonic())
                        worker.connection.send((index, tasks[index]))
                busy = [w for w in self._pool if w.busy is not None]
                now = time.monotonic()
                wait_for = max(0.0, min(w.busy[1] + self.timeout for w in busy) - now)
                ready = wait([x for w in busy for x in (w.connection, w.process.sentinel)], timeout=wait_for)
                for worker in busy:
                    index, started = worker.busy
                    problem = None
                    if worker.connection in ready:
                        try:
                            got, result = worker.connection.recv()
                        except (EOFError, OSError):
                            problem = "crashed"
                        else:
                            worker.busy = None
                            remaining -= 1
                            on_result(result)
                            continue
                    elif worker.process.sentinel in ready:
                        problem = "crashed"
                    elif time.monotonic() - started >= self.timeout:
                        problem = "hung"
                    if problem is None:
                        continue
                    worker.process.join(0.5)
                    code = worker.process.exitcode
                    worker.kill()
                    self._pool.remove(worker)
                    self._pool.append(_Worker(self._context))
                    failures.setdefault(index, []).append(
                        f"the worker hung (no result after {self.timeout:g} s)" if problem == "hung"
                        else f"the worker crashed (exit code {code})")
                    if attempts[index] <= self.retries:
                        queue.appendleft(index)
                    else:
                        remaining -= 1
                        task = tasks[index]
                        on_result(error_result(task, f"{'; then '.join(failures[index])} running {task['role']} "
                                                     f"{task['policy']!r} on {task['scenario']} seed {task['seed']}"
                                                     f" ({attempts[index]} attempts)"))
        except BaseException:
            self.close()  # an interrupted run leaves no worker behind
            raise

    def close(self) -> None:
        pool, self._pool = self._pool, []
        for worker in pool:
            if worker.busy is not None:
                worker.kill()
            else:
                worker.stop()


def get_backend(name: str, workers: Optional[int] = None, address: Optional[str] = None,
                timeout: Optional[float] = None) -> Backend:
    """The backend called ``name``: ``"local"`` (process pool) or ``"ray"`` (a Ray cluster at ``address``)."""
    if name == "local":
        if address:
            raise RegressError("--address is for --backend ray; the local backend runs on this machine")
        return LocalBackend(workers, timeout=timeout)
    if name == "ray":
        try:
            module = importlib.import_module("dv2s_gym.regress.ray_backend")
        except ModuleNotFoundError as error:
            if error.name not in ("dv2s_gym.regress.ray_backend", "ray"):
                raise
            missing = "the ray package" if error.name == "ray" else "dv2s_gym.regress.ray_backend"
            raise RegressError(f"--backend ray needs {missing}, which is not installed; "
                               "install ray (pip install 'ray[default]') or use --backend local") from None
        options: Dict[str, Any] = {"workers": workers, "address": address}
        if timeout is not None and "timeout" in inspect.signature(module.RayBackend).parameters:
            options["timeout"] = timeout
        return module.RayBackend(**options)
    raise RegressError(f"unknown backend {name!r}: use 'local' or 'ray'")
