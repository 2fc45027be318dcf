"""Running episodes on a Ray cluster: ``dv2s regress --backend ray --address HOST:PORT`` (``dv2s mine`` too).

:class:`RayBackend` connects to a running cluster (``ray start --head`` prints its
address) or, without an address, starts a local Ray instance. Episodes run in Ray
actors, one per CPU (or ``workers``), each running the registered function of every task
it gets (:mod:`dv2s_gym.workers.tasks`) and keeping its envs and policies between
tasks. Each actor imports the plug-in modules of the driver
(:func:`~dv2s_gym.workers.tasks.worker_plugins`) before its first task; one that cannot stops the run with a
:class:`~dv2s_gym.workers.errors.WorkerError` naming the module. Results come back as they finish (``ray.wait``). An actor that dies (crash,
out of memory, a lost node) or gives no result within the per-episode timeout is
killed and replaced; its task is retried once, then reported as an error result,
never dropped.

Traces are written on the node that ran the episode, in a scratch folder, and sent
back with the result, so a cluster needs no shared file system for them. The code,
and a custom ``bank_dir``, must be installed at the same paths on every node.
"""

from __future__ import annotations

import logging
import os
import socket
import tempfile
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable, Deque, Dict, Iterable, List, Optional, Tuple

import ray
import ray.exceptions

from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.base import DEFAULT_TIMEOUT, Backend
from dv2s_gym.workers.tasks import (TaskFunction, function_for, gave_up_result, result_object, run_task, start_plugins,
                                     worker_plugins)
from scenario_bank.atomic import atomic_write_bytes

__all__ = ["RayBackend", "RayUnavailableError", "CONNECT_TIMEOUT"]

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for the cluster's address to answer before giving up."""

START_HINT = ("start a cluster with `ray start --head` (it prints the address to pass, host:6379) "
              "or use --backend local")

TOKEN_HINT = ("if the cluster uses token authentication (Ray turns it on for a head started by a user with a "
              "~/.ray/auth_token, which any local Ray run writes), give this process the head's token: "
              "RAY_AUTH_MODE=token RAY_AUTH_TOKEN=<the head's ~/.ray/auth_token>")
"""Ray's own error then says only that it failed to connect (its log says ``InvalidAuthToken``)."""


class RayUnavailableError(WorkerError):
    """No Ray cluster answers at the address given."""


class EpisodeActor:
    """A Ray actor running tasks in one long-lived worker process; it imports the driver's plug-in modules
    (``plugins``) first."""

    def __init__(self, plugins: Optional[List[str]] = None) -> None:
        os.environ["OMP_NUM_THREADS"] = "1"
        self.scratch = Path(tempfile.mkdtemp(prefix="dv2s-ray-traces-"))
        self.problem: Optional[str] = None
        try:
            start_plugins(plugins or [])
        except WorkerError as error:  # told to the driver by start_problem(), which stops the run with it
            self.problem = str(error)

    def start_problem(self) -> Optional[str]:
        """Why this actor cannot run tasks (a plug-in module it could not import), or ``None`` once it is up."""
        return self.problem

    def run(self, function: TaskFunction, task: Dict[str, Any]) -> Tuple[Dict[str, Any], Optional[bytes]]:
        """``(function(task), trace bytes or None)``: the trace goes back to the driver, not a shared disk."""
        local = dict(task)
        if task.get("trace_dir"):
            local["trace_dir"] = str(self.scratch)
        result = run_task(function, local)
        data = None
        trace = result_object(result).get("trace")
        if trace:
            path = Path(trace)
            data = path.read_bytes()
            path.unlink()
        return result, data

    def pid(self) -> int:
        """The actor's process id (for tests)."""
        return os.getpid()


def _host_port(address: str) -> Optional[Tuple[str, int]]:
    rest = address.split("://", 1)[-1]
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return host.strip("[]") or "127.0.0.1", int(port)


def _check_reachable(address: str, timeout: float) -> None:
    """Fail fast, with the fix, when nothing listens at ``address``."""
    if address == "auto":
        return
    target = _host_port(address)
    if target is None:
        raise RayUnavailableError(f"--address {address!r} is not HOST:PORT (e.g. 127.0.0.1:6379 or "
                                  f"ray://HOST:10001); {START_HINT}")
    try:
        with socket.create_connection(target, timeout=timeout):
            pass
    except OSError as error:
        reason = "timed out" if isinstance(error, socket.timeout) else (error.strerror or str(error))
        raise RayUnavailableError(f"Ray is not reachable at {address} ({reason}); {START_HINT}") from None


class RayBackend(Backend):
    """Run tasks in Ray actors.

    Args:
        address: the cluster (``HOST:PORT`` of ``ray start --head``, ``ray://HOST:PORT`` for
            Ray Client, or ``"auto"``); ``None`` starts a local Ray instance for this run.
        workers: actors (default: the cluster's CPUs).
        timeout: seconds one episode may take before its actor counts as hung (default
            :data:`~dv2s_gym.workers.pool.DEFAULT_TIMEOUT`).
        retries: how often a task whose actor died or hung runs again before it is reported
            as an error (default 1).
        connect_timeout: seconds to wait for ``address`` to answer.
    """

    name = "ray"

    def __init__(self, address: Optional[str] = None, workers: Optional[int] = None,
                 timeout: Optional[float] = None, retries: int = 1,
                 connect_timeout: float = CONNECT_TIMEOUT) -> None:
        if workers is not None and int(workers) < 1:
            raise WorkerError(f"--workers must be at least 1, not {workers}")
        if timeout is not None and not float(timeout) > 0:
            raise WorkerError(f"the per-episode timeout must be positive, not {timeout}")
        self.address = address
        self.timeout = float(timeout) if timeout is not None else DEFAULT_TIMEOUT
        self.retries = int(retries)
        self._owns_ray = False
        self._actors: List[Any] = []  # every live actor
        self._idle: List[Any] = []  # actors up and waiting for a task
        self._starting: Dict[Any, Any] = {}  # readiness ref -> actor being started
        self._start_failures = 0
        self._plugins: List[str] = []  # the plug-in modules each actor imports first
        os.environ.setdefault("RAY_DISABLE_USAGE_STATS", "1")
        if not ray.is_initialized():
            self._connect(address, workers, connect_timeout)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = int(workers) if workers is not None else max(1, cpus)
        self._actor_class = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(EpisodeActor)

    def _connect(self, address: Optional[str], workers: Optional[int], connect_timeout: float) -> None:
        options: Dict[str, Any] = {"log_to_driver": False, "logging_level": logging.WARNING,
                                   "configure_logging": False}
        if address:
            _check_reachable(address, connect_timeout)
            options["address"] = address
        else:
            options.update(include_dashboard=False, num_cpus=workers)
        try:
            ray.init(**options)
        except Exception as error:  # ray raises ConnectionError, RuntimeError, ValueError, ... here
            where = f"at {address}" if address else "locally"
            message = " ".join(str(error).split())[:300]
            hint = f"{TOKEN_HINT}; or {START_HINT}" if address else START_HINT
            raise RayUnavailableError(f"cannot connect to Ray {where} ({type(error).__name__}: {message}); "
                                      f"{hint}") from None
        self._owns_ray = True

    def _new_actor(self) -> None:
        actor = self._actor_class.remote(self._plugins)
        self._actors.append(actor)
        self._starting[actor.start_problem.remote()] = actor

    def run(self, tasks: Iterable[Dict[str, Any]], on_result: Callable[[Dict[str, Any]], None]) -> None:
        """Run every task on the cluster; ``on_result`` gets each result here, as it finishes.

        A task's timeout counts from when an actor that is up takes it (starting an actor
        is not counted); a new actor that cannot start three times in a row stops the run
        with :class:`RayUnavailableError`.
        """
        tasks = list(tasks)
        if not tasks:
            return
        functions = [function_for(task) for task in tasks]  # a task of no registered kind fails here, at once
        plugins = worker_plugins()
        if plugins != self._plugins:  # a plug-in registered since the actors started: new actors import it
            self._kill_actors()
            self._plugins = plugins
        queue: Deque[int] = deque(range(len(tasks)))
        attempts: Dict[int, int] = {}
        failures: Dict[int, List[str]] = {}
        running: Dict[Any, Tuple[int, Any, float]] = {}  # ref -> (task index, actor, start)
        try:
            while len(self._actors) < min(self.workers, len(tasks)):
                self._new_actor()
            while queue or running:
                while queue and self._idle:
                    index = queue.popleft()
                    actor = self._idle.pop()
                    attempts[index] = attempts.get(index, 0) + 1
                    running[actor.run.remote(functions[index], tasks[index])] = (index, actor, time.monotonic())
                now = time.monotonic()
                deadlines = [start + self.timeout for _, _, start in running.values()]
                wait_for = max(0.0, min(deadlines) - now) if deadlines else 5.0
                ready, _ = ray.wait(list(running) + list(self._starting), num_returns=1,
                                    timeout=min(wait_for, 5.0))
                for ref in ready:
                    if ref in self._starting:
                        self._started(ref)
                        continue
                    index, actor, _ = running.pop(ref)
                    try:
                        result, trace = ray.get(ref)
                    except ray.exceptions.RayError as error:
                        problem = f"the Ray actor died ({type(error).__name__})"
                    else:
                        self._idle.append(actor)
                        delivered = self._deliver(tasks[index], result, trace)
                        if index in failures:  # finished on a retry: say what happened before
                            delivered = dict(delivered, worker_restarts=list(failures[index]))
                        on_result(delivered)
                        continue
                    self._replace(actor)
                    self._retry_or_fail(tasks, index, problem, attempts, failures, queue, on_result)
                now = time.monotonic()
                for ref, (index, actor, start) in list(running.items()):
                    if now - start < self.timeout:
                        continue
                    del running[ref]
                    self._replace(actor)
                    problem = f"the Ray actor hung (no result after {self.timeout:g} s)"
                    self._retry_or_fail(tasks, index, problem, attempts, failures, queue, on_result)
        except BaseException:
            self.close()  # an interrupted run leaves no actor behind
            raise

    def _started(self, ref) -> None:
        actor = self._starting.pop(ref)
        try:
            problem = ray.get(ref)
        except ray.exceptions.RayError as error:
            self._start_failures += 1
            self._actors.remove(actor)
            if self._start_failures >= 3:
                message = " ".join(str(error).split())[-400:]
                raise RayUnavailableError(
                    f"Ray actors do not start on the cluster at {self.address or 'this machine'} ({message}); "
                    "install dv2s-gym (same version) on every node") from None
            self._new_actor()
            return
        if problem is not None:  # every actor would fail alike: the run stops, naming the module
            raise WorkerError(problem)
        self._start_failures = 0
        self._idle.append(actor)

    def _replace(self, actor) -> None:
        ray.kill(actor, no_restart=True)
        self._actors.remove(actor)
        self._new_actor()

    def _retry_or_fail(self, tasks, index, problem, attempts, failures, queue, on_result) -> None:
        failures.setdefault(index, []).append(problem)
        if attempts[index] <= self.retries:
            queue.appendleft(index)
            return
        on_result(gave_up_result(tasks[index], failures[index], attempts[index]))

    @staticmethod
    def _deliver(task: Dict[str, Any], result: Dict[str, Any], trace: Optional[bytes]) -> Dict[str, Any]:
        if trace is not None and task.get("trace_dir"):
            plain = result_object(result)
            path = Path(task["trace_dir"]) / Path(plain["trace"]).name
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, trace)
            result = dict(plain, trace=str(path))
        return result

    def close(self) -> None:
        """Kill the actors; disconnect from (or stop) the Ray instance this backend started."""
        self._kill_actors()
        if self._owns_ray and ray.is_initialized():
            ray.shutdown()
        self._owns_ray = False

    def _kill_actors(self) -> None:
        actors, self._actors = self._actors, []
        self._idle, self._starting = [], {}
        for actor in actors:
            try:
                ray.kill(actor, no_restart=True)
            except Exception:  # an actor already gone, or the cluster lost
                pass

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            if self._actors:
                self.close()
        except Exception:
            pass
