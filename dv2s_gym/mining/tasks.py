"""Episodes of the miner and the loop in a worker process: :func:`run_mine_task` (one
failure-mining episode, task kind ``"mine"``) and :func:`heldout_task` (one episode of the loop's
held-out evaluation, kind ``"heldout"``, see :mod:`dv2s_gym.mining.heldout`), both registered with
:mod:`dv2s_gym.workers.tasks` when this module is imported.

A mining task is a plain dict (shipped to a pool of :mod:`dv2s_gym.workers`, local or Ray):

- ``kind``: ``"mine"`` (:data:`MINE`); ``role``: ``"mine"``; ``index``: the episode's index in the run;
- ``policy``: policy spec; ``reference``: the reference driver's spec (``None``: no
  avoidability check);
- ``scenario``, ``seed``, ``params``: the scene (see :mod:`dv2s_gym.mining.space`);
- ``env_config``, ``bank_dir``; ``trace_dir``: the folder for a failed episode's trace
  (``<index>.json.gz``; the Ray pool swaps in a local folder and ships the file back);
- ``monitor``: the monitors' settings (a :class:`~dv2s_gym.mining.monitors.MonitorSettings`).

When the failed episode's trace cannot be written (a full disk...), the result is no finished episode: it carries
``write_error`` (:func:`~dv2s_gym.mining.write_errors.write_failure`) and the miner stops before recording it.

The result is the episode record (:class:`~scenario_bank.records.EpisodeRecord`; a failed episode's
``behaviour``: who else was involved and what each side was doing, :mod:`dv2s_gym.mining.behaviour`) of the run's
``episodes.jsonl`` without the sampler fields (the miner adds those). The policy's episode and, when it failed, the reference
driver's episode on the same scene run here, so a record is complete when it arrives.
"""

from __future__ import annotations

import os
import traceback
from typing import Any, Dict, Mapping, Optional

from dv2s_gym.mining.behaviour import extract_behaviour
from dv2s_gym.mining.failure_state import failure_state
from dv2s_gym.mining.write_errors import write_failure
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import DEFAULT_MONITOR, MonitorSettings, detect_failure, robustness
from dv2s_gym.workers.tasks import register
from policies import worker_cache
from policies.evaluation import run_episode
from scenario_bank.failure_types import failure_type
from scenario_bank.records import EpisodeRecord, HeldOutEpisode

__all__ = ["MINE", "HELDOUT", "run_mine_task", "heldout_task", "reference_avoids", "trace_name"]

MINE = "mine"
"""The ``"kind"`` of a failure-mining task."""
HELDOUT = "heldout"
"""The ``"kind"`` of a task of the loop's held-out evaluation."""


def trace_name(index: int) -> str:
    """File name of the trace of failed episode ``index`` in a run's ``traces/`` folder."""
    return f"{index:06d}.json.gz"


def reference_avoids(failure: Optional[Dict[str, Any]], reference_failure: Optional[Dict[str, Any]]) -> bool:
    """True when the reference driver's outcome is less severe than the policy's failure."""
    if failure is None:
        return True
    if reference_failure is None:
        return True
    return _severity(reference_failure["type"]) > _severity(failure["type"])


def _severity(name: str) -> int:
    row = failure_type(name)
    if row is None:
        raise MiningError(f"unknown failure type {name!r}: a monitor's new type needs its row in the failure table "
                          "(scenario_bank.failure_types.register_failure_type)")
    return row.severity


def _episode(task: Dict[str, Any], spec: str):
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.get("bank_dir"), task.get("env_config"))
        policy = worker_cache.policy_for(spec, env_key, env)
        return run_episode(env, policy, task["scenario"], int(task["seed"]), params=task.get("params") or None)
    except Exception:
        if env_key is not None:
            worker_cache.drop_env(env_key)
        raise


_MINE_NULLS = frozenset({"policy", "params", "result", "failure", "rho", "reference", "avoidable", "trace", "error"})
"""The fields a mining task's record always holds (``null`` when ``None``); a failure's ``behaviour`` and
``failure_state`` are there only for a failure."""


def run_mine_task(task: Dict[str, Any]) -> EpisodeRecord:
    """Run the policy (and, if it failed, the reference driver) on the task's scene; the episode record (without
    the sampler fields, the miner's; ``role`` and ``id`` and, when the trace could not be written, ``write_error``
    in its ``extra``)."""
    scene: Dict[str, Any] = {"index": int(task["index"]), "policy": task["policy"], "scenario": task["scenario"],
                             "seed": int(task["seed"]), "params": dict(task.get("params") or {})}
    extra: Dict[str, Any] = {"role": "mine", "id": f"{task['scenario']}/{int(task['seed'])}"}
    outcome: Dict[str, Any] = {}
    nulls = _MINE_NULLS
    monitor: MonitorSettings = task.get("monitor") or DEFAULT_MONITOR
    try:
        result, trace = _episode(task, task["policy"])
        failure = detect_failure(result, trace, monitor)
        outcome["result"] = result.to_json()
        outcome["failure"] = failure.to_json() if failure else None
        outcome["rho"] = robustness(result, failure, monitor)
        if failure is not None:
            nulls = nulls | {"behaviour", "failure_state"}
            behaviour = extract_behaviour(trace, failure)
            outcome["behaviour"] = behaviour.to_dict() if behaviour is not None else None
            outcome["failure_state"] = failure_state(trace, outcome["failure"])
            if task.get("trace_dir"):
                path = os.path.join(task["trace_dir"], trace_name(int(task["index"])))
                try:
                    trace.save(path)
                except OSError as error:  # the run's own file, not the episode: the miner stops, a resume reruns it
                    extra["write_error"] = write_failure(error, path)
                    return _mine_record(scene, outcome, extra, nulls)
                outcome["trace"] = path
            if task.get("reference"):
                ref_result, ref_trace = _episode(task, task["reference"])
                ref_failure = detect_failure(ref_result, ref_trace, monitor)
                outcome["reference"] = {
                    "policy": task["reference"], "failure": ref_failure.to_json() if ref_failure else None,
                    "trajectory_hash": ref_result.trajectory_hash, "collided": ref_result.collided,
                    "min_ttc": ref_result.to_json()["min_ttc"],
                }
                outcome["avoidable"] = reference_avoids(outcome["failure"], outcome["reference"]["failure"])
    except Exception as error:  # reported in the record, never dropped
        message = " ".join(f"{type(error).__name__}: {error}".split())
        if os.environ.get("DV2S_DEBUG"):
            message += "\n" + traceback.format_exc()
        outcome["error"] = message
    return _mine_record(scene, outcome, extra, nulls)


def _mine_record(scene: Dict[str, Any], outcome: Dict[str, Any], extra: Dict[str, Any],
                 nulls: frozenset) -> EpisodeRecord:
    values = {**scene, **outcome}
    if values.get("failure_state") is not None:
        values["failure_state"] = tuple(values["failure_state"])
    return EpisodeRecord(**values, extra=extra, null_fields=nulls)


def _heldout_failure(result, trace, monitor: MonitorSettings) -> Optional[Dict[str, Any]]:
    failure = detect_failure(result, trace, monitor)
    return None if failure is None else failure.to_json()


def heldout_task(task: Mapping[str, Any]) -> HeldOutEpisode:
    """Run one episode in this process: ``task`` has role, policy, scenario, seed, bank_dir,
    env_config, monitor (a :class:`~dv2s_gym.mining.monitors.MonitorSettings`). Returns its
    :class:`~scenario_bank.records.HeldOutEpisode` (an exception becomes ``error``, never a failure)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    episode = HeldOutEpisode(role=task["role"], scenario=task["scenario"], seed=int(task["seed"]),
                             policy=task["policy"])
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.get("bank_dir"), task.get("env_config"))
        policy = worker_cache.policy_for(task["policy"], env_key, env)
        result, trace = run_episode(env, policy, task["scenario"], int(task["seed"]))
        failure = _heldout_failure(result, trace, task.get("monitor") or DEFAULT_MONITOR)
    except Exception as error:  # reported, never counted as a failure of the policy
        if env_key is not None:
            worker_cache.drop_env(env_key)
        return episode.replace(error=" ".join(f"{type(error).__name__}: {error}".split()))
    return episode.replace(failed=failure is not None, failure=failure, result=result.to_json())


register(MINE, run_mine_task)
register(HELDOUT, heldout_task)
