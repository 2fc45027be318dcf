"""Episodes of the miner and the loop in a worker process: :func:`run_mine_task` (one
failure-mining episode, task kind ``"mine"``) and :func:`heldout_task` (one episode of the loop's
held-out evaluation, kind ``"heldout"``, see :mod:`dv2s_gym.loop.heldout`), both registered with
:mod:`dv2s_gym.workers.tasks` when this module is imported.

A mining task is a :class:`MineTask` (the episode's scene and what the worker needs to run and judge it); a pool of
:mod:`dv2s_gym.workers` (local or Ray) ships its JSON object (:meth:`MineTask.to_json`, read back with
:meth:`MineTask.from_json` in the worker): ``kind`` (:data:`MINE`), ``role`` (``"mine"``) and ``id`` beside the
record's fields. ``trace_dir`` is the folder for a failed episode's trace (``<index>.json.gz``; the Ray pool swaps in
a local folder and ships the file back); ``failure_types`` are the failure types the miner detects (its table with
the plug-ins' rows): a worker process that does not detect one of them (a plug-in module that registers later than
when it is imported) records an error for the episode rather than missing the type.

When the failed episode's trace cannot be written (a full disk...), the result is no finished episode: it carries
``write_error`` (:func:`~dv2s_gym.mining.write_errors.write_failure`) and the miner stops before recording it.

The result is the episode record (:class:`~scenario_bank.records.EpisodeRecord`; a failed episode's
``behaviour``: who else was involved and what each side was doing, :mod:`dv2s_gym.mining.behaviour`) of the run's
``episodes.jsonl`` without the sampler fields (the miner adds those). The policy's episode and, when it failed, the reference
driver's episode on the same scene run here, so a record is complete when it arrives.
"""

from __future__ import annotations

import dataclasses
import os
import traceback
from dataclasses import dataclass
from typing import Any, ClassVar, Dict, Mapping, Optional, Tuple

from dv2s_gym.mining.behaviour import extract_behaviour
from dv2s_gym.mining.failure_state import failure_state
from dv2s_gym.mining.write_errors import write_failure
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import (DEFAULT_MONITOR, Failure, MonitorSettings, detect_failure, robustness,
                                      types_without_detector)
from dv2s_gym.workers.tasks import mark_built_in, register, task_id
from policies import worker_cache
from policies.evaluation import run_episode
from scenario_bank.failure_types import failure_table, failure_type
from scenario_bank.records import EpisodeRecord, HeldOutEpisode, ReferenceOutcome

__all__ = ["MINE", "HELDOUT", "MineTask", "HeldOutTask", "run_mine_task", "heldout_task", "reference_avoids",
           "trace_name"]

MINE = "mine"
"""The ``"kind"`` of a failure-mining task."""
HELDOUT = "heldout"
"""The ``"kind"`` of a task of the loop's held-out evaluation."""


@dataclass(frozen=True)
class MineTask:
    """One failure-mining episode for a worker: the scene (``index`` in the run, ``scenario``, env ``seed``,
    sampled ``params``, the scenario's ``family``), the ``policy`` and the ``reference`` driver that decides
    avoidability (``None``: no check), the env (``env_config``, ``bank_dir``: ``None`` for the shipped bank), the
    folder of failed episodes' traces (``trace_dir``; ``None``: keep none), the ``monitor`` settings and the
    ``failure_types`` the miner detects."""

    index: int
    policy: str
    scenario: str
    seed: int
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    reference: Optional[str] = None
    family: Optional[str] = None
    env_config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    bank_dir: Optional[str] = None
    trace_dir: Optional[str] = None
    monitor: MonitorSettings = DEFAULT_MONITOR
    failure_types: Tuple[str, ...] = ()

    kind: ClassVar[str] = MINE
    """Which registered function runs the task (:mod:`dv2s_gym.workers.tasks`)."""
    role: ClassVar[str] = "mine"
    """The episode's role in results and error results."""

    @property
    def id(self) -> str:
        """The episode's id in results: ``"<scenario>/<seed>"``."""
        return task_id(self.scenario, self.seed)

    def to_json(self) -> Dict[str, Any]:
        """The task as a pool ships it (a plain JSON object; :meth:`from_json` reads it back)."""
        return {"kind": self.kind, "role": self.role, "index": self.index, "id": self.id, "policy": self.policy,
                "reference": self.reference, "scenario": self.scenario, "seed": self.seed, "params": self.params,
                "family": self.family, "env_config": self.env_config, "bank_dir": self.bank_dir,
                "trace_dir": self.trace_dir, "monitor": dataclasses.asdict(self.monitor),
                "failure_types": list(self.failure_types)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "MineTask":
        """The task a JSON object holds (:meth:`to_json`'s; the optional fields may be left out); one without an
        episode's ``index``, ``policy``, ``scenario`` or ``seed`` is a :class:`MiningError` naming what is missing."""
        missing = [key for key in ("index", "policy", "scenario", "seed") if data.get(key) is None]
        if missing:
            raise MiningError(f"a mining task needs {', '.join(missing)}; make it with MineTask(...).to_json()")
        return cls(index=int(data["index"]), policy=data["policy"], scenario=data["scenario"],
                   seed=int(data["seed"]), params=dict(data.get("params") or {}), reference=data.get("reference"),
                   family=data.get("family"), env_config=dict(data.get("env_config") or {}),
                   bank_dir=data.get("bank_dir"), trace_dir=data.get("trace_dir"),
                   monitor=MonitorSettings.of(data.get("monitor")),
                   failure_types=tuple(data.get("failure_types") or ()))


@dataclass(frozen=True)
class HeldOutTask:
    """One episode of a loop's held-out evaluation for a worker: the ``policy`` evaluated as ``role`` (``before``,
    ``after``, ``control``...) on bank ``scenario`` at env ``seed``, the env (``bank_dir``: ``None`` for the shipped
    bank, ``env_config``) and the ``monitor`` settings."""

    role: str
    policy: str
    scenario: str
    seed: int
    bank_dir: Optional[str] = None
    env_config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    monitor: MonitorSettings = DEFAULT_MONITOR

    kind: ClassVar[str] = HELDOUT
    """Which registered function runs the task (:mod:`dv2s_gym.workers.tasks`)."""

    def to_json(self) -> Dict[str, Any]:
        """The task as a pool ships it (a plain JSON object; :meth:`from_json` reads it back)."""
        return {"kind": self.kind, "role": self.role, "policy": self.policy, "scenario": self.scenario,
                "seed": self.seed, "bank_dir": self.bank_dir, "env_config": dict(self.env_config),
                "monitor": dataclasses.asdict(self.monitor)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "HeldOutTask":
        """The task a JSON object holds (:meth:`to_json`'s; the optional fields may be left out); one without a
        ``role``, ``policy``, ``scenario`` or ``seed`` is a :class:`MiningError` naming what is missing."""
        missing = [key for key in ("role", "policy", "scenario", "seed") if data.get(key) is None]
        if missing:
            raise MiningError(f"a held-out task needs {', '.join(missing)}; make it with HeldOutTask(...).to_json()")
        return cls(role=data["role"], policy=data["policy"], scenario=data["scenario"], seed=int(data["seed"]),
                   bank_dir=data.get("bank_dir"), env_config=dict(data.get("env_config") or {}),
                   monitor=MonitorSettings.of(data.get("monitor")))


def trace_name(index: int) -> str:
    """File name of the trace of failed episode ``index`` in a run's ``traces/`` folder."""
    return f"{index:06d}.json.gz"


def reference_avoids(failure: Optional[Failure], reference_failure: Optional[Failure]) -> bool:
    """True when the reference driver's outcome is less severe than the policy's failure."""
    if failure is None:
        return True
    if reference_failure is None:
        return True
    return _severity(reference_failure.type) > _severity(failure.type)


def _severity(name: str) -> int:
    row = failure_type(name)
    if row is None:
        raise MiningError(f"unknown failure type {name!r}: a monitor's new type needs its row in the failure table "
                          "(scenario_bank.failure_types.register_failure_type)")
    return row.severity


def _episode(task: MineTask, spec: str):
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.bank_dir, task.env_config)
        policy = worker_cache.policy_for(spec, env_key, env)
        return run_episode(env, policy, task.scenario, task.seed, params=task.params or None)
    except Exception:
        if env_key is not None:
            worker_cache.drop_env(env_key)
        raise


_MINE_NULLS = frozenset({"policy", "params", "result", "failure", "rho", "reference", "avoidable", "trace", "error"})
"""The fields a mining task's record always holds (``null`` when ``None``); a failure's ``behaviour`` and
``failure_state`` are there only for a failure."""


def run_mine_task(task: Mapping[str, Any]) -> EpisodeRecord:
    """Run the policy (and, if it failed, the reference driver) on the scene of ``task`` (a :class:`MineTask`'s JSON
    object); the episode record (without the sampler fields, the miner's; ``role`` and ``id`` and, when the trace
    could not be written, ``write_error`` in its ``extra``)."""
    mine = MineTask.from_json(task)
    scene: Dict[str, Any] = {"index": mine.index, "policy": mine.policy, "scenario": mine.scenario,
                             "seed": mine.seed, "params": dict(mine.params)}
    extra: Dict[str, Any] = {"role": mine.role, "id": mine.id}
    outcome: Dict[str, Any] = {}
    nulls = _MINE_NULLS
    try:
        _check_detects(mine.failure_types)
        result, trace = _episode(mine, mine.policy)
        failure = detect_failure(result, trace, mine.monitor)
        outcome["result"] = result.to_record()
        outcome["failure"] = failure
        outcome["rho"] = robustness(result, failure, mine.monitor)
        if failure is not None:
            nulls = nulls | {"behaviour", "failure_state"}
            outcome["behaviour"] = extract_behaviour(trace, failure)
            outcome["failure_state"] = failure_state(trace, failure)
            if mine.trace_dir:
                path = os.path.join(mine.trace_dir, trace_name(mine.index))
                try:
                    trace.save(path)
                except OSError as error:  # the run's own file, not the episode: the miner stops, a resume reruns it
                    extra["write_error"] = write_failure(error, path)
                    return _mine_record(scene, outcome, extra, nulls)
                outcome["trace"] = path
            if mine.reference:
                outcome["reference"], reference_failure = _reference_outcome(mine)
                outcome["avoidable"] = reference_avoids(failure, reference_failure)
    except Exception as error:  # reported in the record, never dropped
        message = " ".join(f"{type(error).__name__}: {error}".split())
        if os.environ.get("DV2S_DEBUG"):
            message += "\n" + traceback.format_exc()
        outcome["error"] = message
    return _mine_record(scene, outcome, extra, nulls)


def _reference_outcome(task: MineTask) -> Tuple[ReferenceOutcome, Optional[Failure]]:
    """The reference driver's episode on the task's scene, as the record's ``reference``, and its failure."""
    ref_result, ref_trace = _episode(task, task.reference)
    ref_failure = detect_failure(ref_result, ref_trace, task.monitor)
    return ReferenceOutcome(policy=task.reference, failure=ref_failure, trajectory_hash=ref_result.trajectory_hash,
                            collided=ref_result.collided, min_ttc=ref_result.to_record().min_ttc), ref_failure


def _check_detects(names) -> None:
    """Refuse an episode where this process would miss a failure type the miner detects."""
    known = {row.name for row in failure_table()}
    missing = [name for name in names if name not in known] + types_without_detector()
    if missing:
        raise MiningError(f"failure type {', '.join(missing)} is not detected in this worker process: the plug-in "
                          "module that registers it (imported by every worker) must register the type and its "
                          "detector when it is imported, not later")


def _mine_record(scene: Dict[str, Any], outcome: Dict[str, Any], extra: Dict[str, Any],
                 nulls: frozenset) -> EpisodeRecord:
    values = {**scene, **outcome}
    if values.get("failure_state") is not None:
        values["failure_state"] = tuple(values["failure_state"])
    return EpisodeRecord(**values, extra=extra, null_fields=nulls)


def heldout_task(shipped: Mapping[str, Any]) -> HeldOutEpisode:
    """Run one episode in this process: ``shipped`` is a :class:`HeldOutTask`'s JSON object (as a pool ships it).
    Returns its :class:`~scenario_bank.records.HeldOutEpisode` (an exception becomes ``error``, never a
    failure)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    task = HeldOutTask.from_json(shipped)
    episode = HeldOutEpisode(role=task.role, scenario=task.scenario, seed=task.seed, policy=task.policy)
    env_key = None
    try:
        env_key, env = worker_cache.env_for(task.bank_dir, task.env_config)
        policy = worker_cache.policy_for(task.policy, env_key, env)
        result, trace = run_episode(env, policy, task.scenario, task.seed)
        failure = detect_failure(result, trace, task.monitor)
    except Exception as error:  # reported, never counted as a failure of the policy
        if env_key is not None:
            worker_cache.drop_env(env_key)
        return episode.replace(error=" ".join(f"{type(error).__name__}: {error}".split()))
    return episode.replace(failed=failure is not None, failure=failure, result=result.to_record())


register(MINE, run_mine_task)
register(HELDOUT, heldout_task)
mark_built_in(MINE)
mark_built_in(HELDOUT)
