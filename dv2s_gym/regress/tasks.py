"""One regression episode in a worker process: :func:`run_regress_task`, registered as task kind ``"regress"``.

A task is a plain dict, so any pool of :mod:`dv2s_gym.workers` (local processes, Ray) can ship it:

- ``kind``: ``"regress"``;
- ``policy``: policy spec (:func:`policies.registry.load_policy`), e.g. ``"rule"``;
- ``role``: ``"candidate"`` or ``"baseline"``;
- ``scenario``: bank name; ``seed``: the episode's env seed;
- ``env_config``: ``DV2S-v0`` config overrides (dict, may be empty);
- ``bank_dir``: bank folder (``None``: the shipped bank);
- ``trace_dir``: folder for the trace of a failed episode (``None``: keep no trace);
- ``failure``: the failure kinds (:mod:`dv2s_gym.regress.failures`; default collision, off-road, stall);
- ``monitor``: the monitors' settings (an :class:`envs.safety_metrics.MonitorSettings`: its ``stall_seconds``).

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

import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Dict

from dv2s_gym.workers.tasks import error_result, mark_built_in, register, task_id
from policies import worker_cache
from scenario_bank.records import RegressEpisode
from dv2s_gym.regress.failures import apply_failure, failure_kinds, parse_failure
from scenario_bank.failure_types import failure_table, happened
from envs.safety_metrics import MonitorSettings, total_stall_step
from policies.evaluation import run_episode

__all__ = ["KIND", "run_regress_task", "trace_filename"]

KIND = "regress"
"""The ``"kind"`` of a regression task."""


def trace_filename(role: str, scenario: str, seed: int) -> str:
    """File name of a failed episode's trace inside the run's ``traces/`` folder."""
    return f"{scenario}__{int(seed)}__{role}.json.gz"


def run_regress_task(task: Dict[str, Any]) -> RegressEpisode:
    """Run one episode described by ``task`` (see the module docstring) and return its record."""
    for folder in task.get("python_path") or []:  # where a module:attribute policy is found
        if folder not in sys.path:
            sys.path.append(folder)
    unknown = [kind for kind in task.get("failure") or () if kind not in failure_kinds()]
    if unknown:
        return RegressEpisode.from_dict(error_result(task, (
            f"failure type {', '.join(unknown)} is not registered in this worker process: the plug-in module that "
            "registers it (imported by every worker) must register the type and its detector when it is imported, "
            "not later")))
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.get("bank_dir"), task.get("env_config"))
        policy = worker_cache.policy_for(task["policy"], env_key, env, owner=task["role"])  # one instance per role
        started = time.perf_counter()
        result, trace = run_episode(env, policy, task["scenario"], int(task["seed"]))
        seconds = time.perf_counter() - started
    except Exception as error:  # reported as an error episode, never dropped
        if env_key is not None:
            worker_cache.drop_env(env_key)
        message = " ".join(f"{type(error).__name__}: {error}".split())
        if os.environ.get("DV2S_DEBUG"):
            message += "\n" + traceback.format_exc()
        return RegressEpisode.from_dict(error_result(task, message))
    data = result.to_json()
    monitor = MonitorSettings.of(task.get("monitor"))
    stall = total_stall_step(trace, monitor.stall_seconds)
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    data.update(role=task["role"], id=task_id(task["scenario"], task["seed"]), trace=None, seconds=round(seconds, 4),
                stalled=stall is not None, stall_time=None if stall is None else stall * period)
    for row in failure_table():  # every kind decided as the miner decides it: by the detector registry
        if row.result_field:
            data[row.result_field] = happened(row.name, result, trace, monitor, recorded=data)
    apply_failure(data, parse_failure(task.get("failure")))
    trace_dir = task.get("trace_dir")
    if data["failed"] and trace_dir:
        path = Path(trace_dir) / trace_filename(task["role"], task["scenario"], task["seed"])
        trace.save(path)
        data["trace"] = str(path)
    return RegressEpisode.from_dict(data)


register(KIND, run_regress_task)
mark_built_in(KIND)
