"""Where episodes of regress and mining run: a pool of local processes, or Ray.

A :class:`Backend` takes task dicts (see :mod:`dv2s_gym.workers.tasks`) and hands each
result to a callback as soon as it finishes. :class:`LocalBackend` runs one process per
worker (``forkserver`` context where available, else ``spawn``; ``OMP_NUM_THREADS=1``), each running
the registered function of every task it gets and keeping its envs and policies between
tasks. Before its first task, each worker imports the plug-in modules of the process that started it
(:func:`~dv2s_gym.workers.tasks.worker_plugins`: a plug-in's failure type and detector register there too); a
worker that cannot import one stops the run with a :class:`WorkerError` naming the module. With each result a
worker sends the user's files it has read since its last one (:func:`scenario_bank.read_files.unsent_reads`), kept
in :attr:`LocalBackend.files_read`; a file whose SHA-256 changed since a worker first sent it stops the run
(:class:`~scenario_bank.read_files.ReadFilesError`, before the result read with it is handed on). A worker that dies mid-episode (segfault, ``os._exit``, out of memory) or gives no
result within the per-episode timeout is killed and replaced; its task is retried once
(``retries``), then reported as an error result ``{"error": ..., "id", "role", ...}`` -
never silently dropped; a task that finishes on a retry carries ``"worker_restarts"``, the
problems of its earlier attempts.

:func:`dv2s_gym.workers.backends.get_backend` picks one by name (``"local"``, ``"ray"``: the Ray backend lives
in :mod:`dv2s_gym.workers.ray_pool`, or one registered there).
"""

from __future__ import annotations

import multiprocessing
import os
import time
import warnings
from collections import deque
from dataclasses import astuple, replace
from multiprocessing.connection import wait
from typing import Any, Callable, Deque, Dict, Iterable, List, Optional, Set, Tuple

from scenario_bank.read_files import ReadFile, changed_while_running, unsent_reads, watch
from dv2s_gym.workers.base import DEFAULT_TIMEOUT, Backend, OnResult, default_workers
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.tasks import (TaskFunction, function_for, gave_up_result, result_object, run_task,
                                    start_plugins, task_modules, worker_plugins)
import policies.evaluation

__all__ = ["Backend", "LocalBackend", "default_workers", "DEFAULT_TIMEOUT"]

_READY = "ready"
_CANNOT_START = "cannot start"
_PRELOAD = ("dv2s_gym.workers.pool", "envs.dv2s_env", "policies.evaluation")


def _worker_main(connection, plugins: List[str]) -> None:
    """A pool process: watch what it reads, import the ``plugins`` modules, then receive ``(index, function,
    task)``, send ``(index, result, reads)`` (``reads``: the user's files read since the last result,
    :func:`scenario_bank.read_files.unsent_reads`, as tuples); ``None`` stops it. A plug-in that cannot be imported
    is sent as ``(_CANNOT_START, message)``."""
    os.environ["OMP_NUM_THREADS"] = "1"
    try:
        import envs.dv2s_env  # noqa: F401  (the slow imports happen before the first episode's clock starts)
        from scenic.core.dynamics import StuckBehaviorWarning

        # Scenic's wall-clock "behavior is taking a long time" fires on a loaded machine and would print
        # through the progress bars; a behaviour that is really stuck hits the env's step_time_limit.
        warnings.filterwarnings("ignore", category=StuckBehaviorWarning)
    except Exception:  # reported by the first task instead
        pass
    watch()  # the files the plug-ins read, here only (a helper imported inside a detector), are the run's too
    try:
        start_plugins(plugins)
    except WorkerError as error:
        _send_quietly(connection, (_CANNOT_START, str(error)))
        return
    try:
        connection.send(_READY)  # imports done: episode timeouts count from here
    except (OSError, KeyboardInterrupt):
        return
    while True:
        try:
            message = connection.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if message is None:
            return
        index, function, task = message
        result = run_task(function, task)
        try:
            connection.send((index, result, [astuple(read) for read in unsent_reads()]))
        except (OSError, KeyboardInterrupt):
            return


def _send_quietly(connection, message: Any) -> None:
    try:
        connection.send(message)
    except (OSError, KeyboardInterrupt):
        pass


class _Worker:
    def __init__(self, context, plugins: List[str]) -> None:
        parent, child = context.Pipe()
        self.connection = parent
        self.process = context.Process(target=_worker_main, args=(child, list(plugins)), daemon=True,
                                       name="dv2s-worker")
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
        self.ready = False  # set when the process has imported everything and waits for tasks
        self.seen: Set[Tuple[Any, ...]] = set()  # (bank, config, scenario) it has run: compiled, cached
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


class _ScenarioQueue:
    """Pending task indices grouped by scenario (and bank and env config), in submission order.

    Compiling a scenario is the slow part of a worker's first episode of it, so a worker
    takes tasks of scenarios it has already run, then of scenarios no worker has run yet,
    and only then shares another worker's (the one with the most left): each scenario is
    compiled by as few workers as possible.
    """

    def __init__(self, tasks: List[Dict[str, Any]]) -> None:
        self._groups: Dict[Tuple[Any, ...], Deque[int]] = {}
        self._group_of: List[Tuple[Any, ...]] = []
        for task in tasks:
            self.append(task)

    def append(self, task: Dict[str, Any]) -> int:
        """Queue one more task (it gets the next index); its index."""
        key = (task.get("bank_dir"), repr(sorted((task.get("env_config") or {}).items())), task["scenario"])
        self._group_of.append(key)
        self._groups.setdefault(key, deque()).append(len(self._group_of) - 1)
        return len(self._group_of) - 1

    def __bool__(self) -> bool:
        return any(self._groups.values())

    def group(self, index: int) -> Tuple[Any, ...]:
        return self._group_of[index]

    def push_front(self, index: int) -> None:
        self._groups[self._group_of[index]].appendleft(index)

    def pop_for(self, seen: Set[Tuple[Any, ...]], others: List[Set[Tuple[Any, ...]]]) -> int:
        pending = [key for key, queue in self._groups.items() if queue]
        own = [key for key in pending if key in seen]
        fresh = [key for key in pending if not any(key in other for other in others)]
        if own:
            key = min(own, key=lambda k: self._groups[k][0])  # the oldest task a worker has compiled
        elif fresh:
            key = fresh[0]
        else:
            key = max(pending, key=lambda k: len(self._groups[k]))
        return self._groups[key].popleft()


class LocalBackend(Backend):
    """A pool of local worker processes (spawn or forkserver context; never a plain fork of the caller).

    Args:
        workers: processes (default: every core this process may use).
        timeout: seconds one episode may take before its worker counts as hung and is
            killed (default :data:`DEFAULT_TIMEOUT`; the first episode of a scenario in a
            worker includes compiling it).
        retries: how often a task whose worker crashed or hung is run again before it is
            reported as an error (default 1).
        start_method: ``"forkserver"`` (default where the platform has it: a server process
            imports the simulator once and every worker is forked from it, so starting or
            replacing a worker is quick) or ``"spawn"`` (each worker imports everything).
    """

    name = "local"

    def __init__(self, workers: Optional[int] = None, timeout: Optional[float] = None, retries: int = 1,
                 start_method: Optional[str] = None) -> None:
        if workers is not None and int(workers) < 1:
            raise WorkerError(f"--workers must be at least 1, not {workers}")
        if timeout is not None and not float(timeout) > 0:
            raise WorkerError(f"the per-episode timeout must be positive, not {timeout}")
        if start_method is None:
            start_method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        if start_method not in ("spawn", "forkserver"):
            raise WorkerError(f"start_method must be 'spawn' or 'forkserver', not {start_method!r}")
        self.workers = int(workers) if workers is not None else default_workers()
        self.timeout = float(timeout) if timeout is not None else DEFAULT_TIMEOUT
        self.retries = int(retries)
        self._context = multiprocessing.get_context(start_method)
        if start_method == "forkserver":
            # imported once by the server (it starts with the first worker), inherited by every fork
            self._context.set_forkserver_preload(list(_PRELOAD) + task_modules())
        self._pool: List[_Worker] = []
        self._plugins: List[str] = []  # the plug-in modules the workers in the pool imported
        self.files_read: Dict[str, ReadFile] = {}
        """The user's files the workers read (:func:`scenario_bank.read_files.user_reads`), by path: each with the
        labels of every worker that read it and the SHA-256 the first one saw."""

    def _note_read(self, read: ReadFile) -> None:
        """Keep a file a worker read; one whose SHA-256 differs from the one first seen stops the run
        (:class:`~scenario_bank.read_files.ReadFilesError`): it changed while the run ran."""
        known = self.files_read.get(read.path)
        if known is not None and known.sha256 != read.sha256:
            raise changed_while_running(read.path, known.sha256, read.sha256)
        if known is None:
            self.files_read[read.path] = read
        elif not set(read.labels) <= set(known.labels):
            self.files_read[read.path] = replace(known, labels=tuple(sorted(set(known.labels) | set(read.labels))))

    def _ensure(self, count: int) -> None:
        plugins = worker_plugins()
        if plugins != self._plugins:  # a plug-in registered since the workers started: new workers import it
            self.close()
            self._plugins = plugins
        self._pool = [w for w in self._pool if w.process.is_alive()]
        while len(self._pool) < count:
            self._pool.append(_Worker(self._context, self._plugins))

    streams = True

    def run(self, tasks: Iterable[Dict[str, Any]], on_result: OnResult,
            more: Optional[Callable[[], Iterable[Dict[str, Any]]]] = None) -> None:
        """Run every task; ``on_result(result)`` for each as it finishes (see :meth:`Backend.run`).

        ``more``: called after each round of finished results has been handed to ``on_result``; the
        tasks it returns are queued too (with the same timeouts, retries and scenario affinity), so a
        caller can keep the workers busy with tasks that depend on earlier results. The call returns
        when every task, first or added, has a result.
        """
        tasks = list(tasks)
        if not tasks and more is not None:
            tasks = list(more())
        if not tasks:
            return
        functions = [function_for(task) for task in tasks]  # a task of no registered kind fails here, at once
        queue = _ScenarioQueue(tasks)
        attempts: Dict[int, int] = {}
        failures: Dict[int, List[str]] = {}
        remaining = len(tasks)
        failed_starts = 0
        self._ensure(self.workers if more is not None else min(self.workers, len(tasks)))  # more may come
        try:
            while remaining:
                finished: List[Dict[str, Any]] = []
                self._dispatch(queue, tasks, functions, attempts)
                deadlines = [w.busy[1] + self.timeout for w in self._pool if w.busy is not None]
                wait_for = max(0.0, min(deadlines) - time.monotonic()) if deadlines else None
                ready = wait([x for w in self._pool for x in (w.connection, w.process.sentinel)], timeout=wait_for)
                for worker in list(self._pool):
                    problem, result = self._receive(worker, ready, failures)
                    if result is not None:
                        remaining -= 1
                        finished.append(result)
                    if problem is None:
                        continue
                    code = self._replace(worker)
                    if worker.busy is None:  # died before taking a task: the process cannot start
                        failed_starts += 1
                        if failed_starts > 2 * self.workers:
                            raise WorkerError(
                                f"worker processes exit while starting (exit code {code}); a script "
                                "that starts a run must do so under `if __name__ == '__main__':`, and "
                                "`python -c 'import dv2s_gym.workers.pool'` must work")
                        continue
                    index = worker.busy[0]
                    failures.setdefault(index, []).append(
                        f"the worker hung (no result after {self.timeout:g} s)" if problem == "hung"
                        else f"the worker crashed (exit code {code})")
                    if attempts[index] <= self.retries:
                        queue.push_front(index)
                    else:
                        remaining -= 1
                        finished.append(gave_up_result(tasks[index], failures[index], attempts[index]))
                # idle workers get their next task before the results are handled (saved, reported),
                # so they do not wait for that
                self._dispatch(queue, tasks, functions, attempts)
                for result in finished:
                    on_result(result)
                if more is not None and finished:
                    added = list(more())
                    for task in added:
                        functions.append(function_for(task))
                        tasks.append(task)
                        queue.append(task)
                    remaining += len(added)
        except BaseException:
            self.close()  # an interrupted run leaves no worker behind
            raise

    def _receive(self, worker: "_Worker", ready: List[Any], failures: Dict[int, List[str]]
                 ) -> Tuple[Optional[str], Optional[Dict[str, Any]]]:
        """``(problem, result)`` of one worker after a wait: the result of the task it finished, or its problem
        (``"crashed"``, ``"hung"``), or neither (it started, or is still at work)."""
        if worker.connection in ready:
            try:
                message = worker.connection.recv()
            except (EOFError, OSError):
                return "crashed", None
            if message == _READY:
                worker.ready = True
                return None, None
            if isinstance(message, tuple) and message[0] == _CANNOT_START:
                raise WorkerError(message[1])  # every worker would fail alike: the run stops, naming the module
            _, result, reads = message
            for read in reads:
                self._note_read(ReadFile(*read))
            if worker.busy[0] in failures:  # finished on a retry: say what happened before
                result = dict(result_object(result), worker_restarts=list(failures[worker.busy[0]]))
            worker.busy = None
            return None, result
        if worker.process.sentinel in ready:
            return "crashed", None
        if worker.busy is not None and time.monotonic() - worker.busy[1] >= self.timeout:
            return "hung", None
        return None, None

    def _replace(self, worker: "_Worker") -> Optional[int]:
        """Kill a crashed or hung worker and start another in its place; the old one's exit code."""
        worker.process.join(0.5)
        code = worker.process.exitcode
        worker.kill()
        self._pool.remove(worker)
        self._pool.append(_Worker(self._context, self._plugins))
        return code

    def _dispatch(self, queue: "_ScenarioQueue", tasks: List[Dict[str, Any]], functions: List[TaskFunction],
                  attempts: Dict[int, int]) -> None:
        """Send a task to every started, idle worker while tasks are left."""
        for worker in self._pool:
            if worker.ready and worker.busy is None and queue:
                index = queue.pop_for(worker.seen, [w.seen for w in self._pool if w is not worker])
                worker.seen.add(queue.group(index))
                attempts[index] = attempts.get(index, 0) + 1
                worker.busy = (index, time.monotonic())
                try:
                    worker.connection.send((index, functions[index], tasks[index]))
                except OSError:  # the worker just died: its sentinel reports it on the next wait
                    pass

    def close(self) -> None:
        pool, self._pool = self._pool, []
        for worker in pool:
            if worker.busy is not None:
                worker.kill()
            else:
                worker.stop()
