"""One regression episode in a worker process: :func:`run_regress_task`, registered as task kind ``"regress"``.

A task is a :class:`RegressTask`; a pool of :mod:`dv2s_gym.workers` (local processes, Ray) ships its JSON object
(:meth:`RegressTask.to_json`), which :func:`run_regress_task` reads back (:meth:`RegressTask.from_json`):

- ``kind``: ``"regress"``;
- ``policy``: policy spec (:func:`policies.registry.load_policy`), e.g. ``"rule"``;
- ``role``: ``"candidate"`` or ``"baseline"``;
- ``scenario``: bank name; ``seed``: the episode's env seed;
- ``env_config``: ``DV2S-v0`` config overrides (dict, may be empty);
- ``bank_dir``: bank folder (``None``: the shipped bank);
- ``trace_dir``: folder for the trace of a failed episode (``None``: keep no trace);
- ``failure``: the failure kinds (:mod:`dv2s_gym.regress.failures`; ``None``: collision, off-road, stall);
- ``monitor``: the monitors' settings (an :class:`envs.safety_metrics.MonitorSettings`: its ``stall_seconds``);
- ``python_path``: folders a ``module:attribute`` policy spec is found in (added to ``sys.path``).

Every failure type with a ``result_field`` is recorded in that field as ``dv2s mine`` decides it
(:func:`scenario_bank.failure_types.happened`): a type registered at run time
(:func:`scenario_bank.failure_types.register_failure_type`) and a built-in type whose detector a plug-in replaced
(:func:`dv2s_gym.mining.monitors.register_detector`) by running that detector on the episode's trace, the other
built-in types by the facts the episode records (``collided``, ``off_road``, ``stalled``). Every worker process imports the
plug-in modules of the process that started it before its first task (:mod:`scenario_bank.plugins`), so a
plug-in module that registers the type and its detector when it is imported registers them there too; a task
naming a type this process still does not know comes back as an error result that says so.

:func:`run_regress_task` returns the episode's :class:`~scenario_bank.records.RegressEpisode`:
``EpisodeResult.to_json()`` plus ``role``, ``id`` (``"<scenario>/<seed>"``), ``trace`` (the saved trace's path or
``None``), ``stalled`` and ``stall_time`` (when the ego's total standing time on a free road reached the monitor's
``stall_seconds``: :func:`envs.safety_metrics.total_stall_step`), with ``failed`` and ``failure_kinds`` set from
the task's failure kinds, and in its ``extra`` ``seconds`` (the episode's wall time; the runner keeps it apart
from the result). An exception inside the episode comes back as an error result (``id``, ``role``, ``scenario``,
``seed``, ``error`` and a ``null`` trace) instead of propagating: it is kept in the report, never dropped.

Envs and loaded policies are cached per process between tasks (making an env and
compiling a scenario is the slow part); the caches are keyed by bank, env config and
spec, so a worker serves any mix of tasks.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any, ClassVar, Dict, Mapping, Optional, Tuple

from dv2s_gym.workers.tasks import error_result, mark_built_in, register, task_id
from policies import worker_cache
from scenario_bank.records import RegressEpisode
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.failures import apply_failure, failure_kinds, parse_failure
from scenario_bank.failure_types import failure_table, happened
from envs.safety_metrics import MonitorSettings, total_stall_step
from policies.evaluation import run_episode

__all__ = ["KIND", "RegressTask", "run_regress_task", "trace_filename"]

KIND = "regress"
"""The ``"kind"`` of a regression task."""


@dataclasses.dataclass(frozen=True)
class RegressTask:
    """One regression episode for a worker (the module docstring says what each field holds): the ``policy`` run
    as ``role`` on ``scenario`` at env ``seed``, the env (``env_config``, ``bank_dir``), the folder of failed
    episodes' traces (``trace_dir``), the ``failure`` kinds, the ``monitor`` settings and the ``python_path`` of a
    ``module:attribute`` policy."""

    policy: str
    role: str
    scenario: str
    seed: int
    env_config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    bank_dir: Optional[str] = None
    trace_dir: Optional[str] = None
    failure: Optional[Tuple[str, ...]] = None
    monitor: MonitorSettings = MonitorSettings()
    python_path: Tuple[str, ...] = ()

    kind: ClassVar[str] = KIND
    """Which registered function runs the task (:mod:`dv2s_gym.workers.tasks`)."""

    @property
    def id(self) -> str:
        """The episode's id in results: ``"<scenario>/<seed>"``."""
        return task_id(self.scenario, self.seed)

    @property
    def key(self) -> Tuple[str, str]:
        """``(id, role)``: the episode's place in the run (:attr:`scenario_bank.records.RegressEpisode.key`)."""
        return self.id, self.role

    def to_json(self) -> Dict[str, Any]:
        """The task as a pool ships it (a plain JSON object; :meth:`from_json` reads it back)."""
        return {"kind": self.kind, "policy": self.policy, "role": self.role, "scenario": self.scenario,
                "seed": self.seed, "env_config": dict(self.env_config), "bank_dir": self.bank_dir,
                "trace_dir": self.trace_dir, "failure": None if self.failure is None else list(self.failure),
                "monitor": dataclasses.asdict(self.monitor), "python_path": list(self.python_path)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "RegressTask":
        """The task a JSON object holds (:meth:`to_json`'s; the optional fields may be left out); one without a
        ``policy``, ``role``, ``scenario`` or ``seed`` is a :class:`RegressError` naming what is missing."""
        missing = [key for key in ("policy", "role", "scenario", "seed") if data.get(key) is None]
        if missing:
            raise RegressError(f"a regression task needs {', '.join(missing)}; make it with RegressTask(...).to_json()")
        failure = data.get("failure")
        return cls(policy=data["policy"], role=data["role"], scenario=data["scenario"], seed=int(data["seed"]),
                   env_config=dict(data.get("env_config") or {}), bank_dir=data.get("bank_dir"),
                   trace_dir=data.get("trace_dir"), failure=None if failure is None else tuple(failure),
                   monitor=MonitorSettings.of(data.get("monitor")), python_path=tuple(data.get("python_path") or ()))


def trace_filename(role: str, scenario: str, seed: int) -> str:
    """File name of a failed episode's trace inside the run's ``traces/`` folder."""
    return f"{scenario}__{int(seed)}__{role}.json.gz"


def run_regress_task(shipped: Mapping[str, Any]) -> RegressEpisode:
    """Run the episode of the task ``shipped`` (a :class:`RegressTask`'s JSON object, as a pool ships it; see the
    module docstring) and return its record."""
    task = RegressTask.from_json(shipped)
    for folder in task.python_path:  # where a module:attribute policy is found
        if folder not in sys.path:
            sys.path.append(folder)
    unknown = [kind for kind in task.failure or () if kind not in failure_kinds()]
    if unknown:
        return RegressEpisode.from_dict(error_result(shipped, (
            f"failure type {', '.join(unknown)} is not registered in this worker process: the plug-in module that "
            "registers it (imported by every worker) must register the type and its detector when it is imported, "
            "not later")))
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.bank_dir, task.env_config)
        policy = worker_cache.policy_for(task.policy, env_key, env, owner=task.role)  # one instance per role
        started = time.perf_counter()
        result, trace = run_episode(env, policy, task.scenario, task.seed)
        seconds = time.perf_counter() - started
    except Exception as error:  # reported as an error episode, never dropped
        if env_key is not None:
            worker_cache.drop_env(env_key)
        message = " ".join(f"{type(error).__name__}: {error}".split())
        if os.environ.get("DV2S_DEBUG"):
            message += "\n" + traceback.format_exc()
        return RegressEpisode.from_dict(error_result(shipped, message))
    data = result.to_json()
    monitor = task.monitor
    stall = total_stall_step(trace, monitor.stall_seconds)
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    data.update(role=task.role, id=task.id, trace=None, seconds=round(seconds, 4),
                stalled=stall is not None, stall_time=None if stall is None else stall * period)
    for row in failure_table():  # every kind decided as the miner decides it: by the detector registry
        if row.result_field:
            data[row.result_field] = happened(row.name, result, trace, monitor, recorded=data)
    apply_failure(data, parse_failure(task.failure))
    if data["failed"] and task.trace_dir:
        path = Path(task.trace_dir) / trace_filename(task.role, task.scenario, task.seed)
        trace.save(path)
        data["trace"] = str(path)
    return RegressEpisode.from_dict(data)


register(KIND, run_regress_task)
mark_built_in(KIND)
