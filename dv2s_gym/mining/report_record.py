"""The typed mining report: :class:`MineReport`, the object ``report.json`` holds, as
:func:`dv2s_gym.mining.report.build_report` makes it and the report's renderings read it.

Every part of it is a typed record: the run's ``counts`` (:class:`MineCounts`), each sampler's figures
(:class:`SamplerSummary`) and each scenario's (:class:`ScenarioSummary`), the behaviour clusters
(:class:`ClusterEntry`, each with its representative failure and its conversion, a
:class:`~dv2s_gym.mining.conversion.record.ConversionRecord`), the failures (:class:`FailureEntry`), the rejected
conversions (:class:`RejectedConversion`), the episodes that ended in an error (:class:`EpisodeError`) or were
finished by a new worker (:class:`WorkerRestart`). The run's ``settings`` (``settings.json`` as recorded) and the
failure rate under the scenarios' own distributions (``failure_rate``, the JSON object of a
:class:`~dv2s_gym.mining.sampling.rate.FailureRate`) stay JSON objects. Their schema is in the docstring of
:mod:`dv2s_gym.mining.report`.

Each is a :class:`~scenario_bank.records.JsonRecord`: :meth:`from_dict` reads the JSON object (a
:class:`~scenario_bank.records.RecordError` names a field of the wrong kind, ``mining report field
'counts.failures'``), :meth:`to_dict` writes back exactly the object read (unknown keys kept in ``extra``, ``null``
where it was), so ``report.json`` is ``MineReport.to_dict()``; read a ``report.json`` with
``MineReport.from_dict(json.loads(text))`` before handing it to the renderings, which take the record only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple

from dv2s_gym.mining.behaviour import Behaviour, behaviour_of
from dv2s_gym.mining.conversion.record import ConversionRecord
from dv2s_gym.mining.family import record_family
from scenario_bank.errors import WrongTypeError
from scenario_bank.records import EpisodeRecord, Failure, JsonRecord, ReferenceOutcome

__all__ = ["MineReport", "MineCounts", "SamplerSummary", "ScenarioSummary", "FailureEntry", "ClusterEntry",
           "RejectedConversion", "EpisodeError", "WorkerRestart", "mine_report"]


@dataclass(frozen=True, eq=False)
class MineCounts(JsonRecord):
    """A mining run's counts: finished ``episodes`` and those that ended in an error (``errors``) or were finished
    by a new worker (``worker_restarts``); ``failures`` (by type), ``avoidable``, ``unavoidable`` and of unknown
    avoidability; distinct ``clusters`` (``behaviours``), (scenario family, failure type) pairs, failing families,
    avoidable and unavoidable clusters; the conversions (``converted``, ``kept``, ``merged``, ``rejected`` and by
    stage), their seconds, and the failing parameter values the conversion judge compared or could not compare."""

    episodes: int = 0
    errors: int = 0
    worker_restarts: int = 0
    failures: int = 0
    failures_by_type: Mapping[str, int] = field(default_factory=dict)
    collisions: Optional[int] = None
    """Failures of a type that is the ego touching an actor (``None`` in a report written before they were counted)."""
    stalls: Optional[int] = None
    """Failures of a type that is the ego standing (``None`` in a report written before they were counted)."""
    avoidable: int = 0
    unavoidable: int = 0
    avoidability_unknown: int = 0
    clusters: int = 0
    behaviours: int = 0
    scenario_failure_types: int = 0
    scenarios_failing: int = 0
    avoidable_clusters: int = 0
    unavoidable_clusters: int = 0
    converted: int = 0
    kept: int = 0
    merged: int = 0
    rejected: int = 0
    rejected_by_stage: Mapping[str, int] = field(default_factory=dict)
    conversion_seconds: Mapping[str, Any] = field(default_factory=dict)
    conversion_stage_seconds: Mapping[str, Any] = field(default_factory=dict)
    parameters_compared: int = 0
    parameters_not_compared: int = 0
    parameters_not_compared_by_reason: Mapping[str, int] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "mining counts"


@dataclass(frozen=True, eq=False)
class SamplerSummary(JsonRecord):
    """One sampler's figures in a mining run: its ``episodes`` and ``errors``, ``failures`` and avoidable ones, each
    per 100 episodes (``{"value", "low", "high", "count", "n"}``, Wilson 95 %), distinct ``clusters`` and avoidable
    ones (also per 100 episodes), the episode of its first failure and its ``discovery`` curve (``[[episodes,
    distinct clusters], ...]``)."""

    episodes: int = 0
    errors: int = 0
    failures: int = 0
    avoidable_failures: int = 0
    failures_per_100: Optional[Mapping[str, Any]] = None
    avoidable_failures_per_100: Optional[Mapping[str, Any]] = None
    clusters: int = 0
    avoidable_clusters: int = 0
    clusters_per_100: Optional[float] = None
    avoidable_clusters_per_100: Optional[float] = None
    episodes_to_first_failure: Optional[int] = None
    discovery: Tuple[Any, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "sampler summary"


@dataclass(frozen=True, eq=False)
class ScenarioSummary(JsonRecord):
    """One scenario's figures in a mining run (``Scenario`` in :mod:`dv2s_gym.mining.report`): its ``episodes``,
    ``errors``, ``failures`` (``avoidable``, ``unavoidable``, ``unknown``), the sampled ``failure_rate``
    (``{"value", "low", "high", "count"}``, Wilson 95 %), the ``estimated_rate`` under its own parameter distribution
    (``None`` when not estimated), its failures by type and the number of types (``failure_types``), its
    ``clusters`` (and avoidable ones) and the conversions of them (``converted``, ``kept``)."""

    episodes: Optional[int] = None
    errors: Optional[int] = None
    failures: Optional[int] = None
    avoidable: Optional[int] = None
    unavoidable: Optional[int] = None
    unknown: Optional[int] = None
    failure_rate: Optional[Mapping[str, Any]] = None
    estimated_rate: Optional[Mapping[str, Any]] = None
    failures_by_type: Optional[Mapping[str, int]] = None
    failure_types: Optional[int] = None
    clusters: Optional[int] = None
    avoidable_clusters: Optional[int] = None
    converted: Optional[int] = None
    kept: Optional[int] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "scenario summary"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


def _behaviour(data: Mapping[str, Any]) -> Dict[str, Any]:
    """The :class:`Behaviour` of a record's ``behaviour`` JSON object (none when it has none)."""
    value = data.get("behaviour")
    return {"behaviour": Behaviour.from_dict(value).complete()} if isinstance(value, Mapping) else {}


def _behaviour_json(record: Any, out: Dict[str, Any]) -> Dict[str, Any]:
    """``out`` (a record's JSON object) with its :class:`Behaviour` written as its JSON object."""
    if isinstance(record.behaviour, Behaviour):
        out["behaviour"] = record.behaviour.to_dict()
    return out


@dataclass(frozen=True, eq=False)
class FailureEntry(JsonRecord):
    """One failed episode as the report lists it (``Failure`` in :mod:`dv2s_gym.mining.report`).

    The episode's ``index``, the ``sampler`` that drew it, its ``scenario``, scenario ``family``
    (:func:`~dv2s_gym.mining.family.record_family`), env ``seed`` and sampled ``params``; the failure's ``type``, its
    ``kind`` (the type refined by the collision type), ``time``, the actor it was with (``with_actor``, JSON
    ``with``) and that actor's kind (``with_kind``), the ``collision_type`` and the failure's ``min_ttc``; the
    episode's robustness ``rho``, whether the reference driver avoided it (``avoidable``; ``None``: unknown) and the
    reference driver's outcome (``reference``), the ``cluster`` id, the failure's ``behaviour``
    (:class:`~dv2s_gym.mining.behaviour.Behaviour`) and the saved ``trace`` (relative to the run folder). Every
    field is written, ``null`` when ``None``.
    """

    index: Optional[int] = None
    sampler: Optional[str] = None
    scenario: Optional[str] = None
    family: Optional[str] = None
    seed: Optional[int] = None
    params: Optional[Mapping[str, Any]] = None
    type: Optional[str] = None
    kind: Optional[str] = None
    time: Optional[float] = None
    with_actor: Optional[Any] = None
    with_kind: Optional[str] = None
    collision_type: Optional[str] = None
    min_ttc: Optional[float] = None
    rho: Optional[float] = None
    avoidable: Optional[bool] = None
    reference: Optional[ReferenceOutcome] = None
    cluster: Optional[str] = None
    behaviour: Optional[Behaviour] = None
    trace: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"with": "with_actor"}
    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"behaviour": "object"}
    _WHAT: ClassVar[str] = "failure entry"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return _behaviour(data)

    def to_dict(self) -> Dict[str, Any]:
        return _behaviour_json(self, super().to_dict())

    @classmethod
    def of(cls, record: EpisodeRecord, cluster: Optional[str], default_sampler: str) -> "FailureEntry":
        """The entry of the failed episode ``record`` in ``cluster`` (``default_sampler``: the run's sampler, for a
        record that does not name its own)."""
        # a record without a failure (the report lists none) would list the type "None", as str(None) reads
        failure = record.failure if record.failure is not None else Failure(type="None", null_fields=frozenset())
        return cls(index=int(record.index), sampler=str(record.sampler or default_sampler), scenario=record.scenario,
                   family=record_family(record), seed=record.seed, params=dict(record.params or {}),
                   type=failure.type, kind=failure.kind, time=failure.time, with_actor=failure.with_,
                   with_kind=failure.with_kind, collision_type=failure.collision_type, min_ttc=failure.min_ttc,
                   rho=record.rho,
                   avoidable=record.avoidable, reference=record.reference, cluster=cluster,
                   behaviour=behaviour_of(record), trace=record.trace)


@dataclass(frozen=True, eq=False)
class ClusterEntry(JsonRecord):
    """One behaviour cluster as the report lists it (``Cluster`` in :mod:`dv2s_gym.mining.report`).

    Its ``id`` and, from it, ``kind`` (the failure class) and ``region`` (the id after family and class); its
    ``representative`` failure (:class:`FailureEntry`) and that one's ``scenario``, ``family``, ``type`` and
    ``behaviour``; every scenario its failures ran in (``scenarios``); the members' counts (``size``, ``avoidable``,
    ``unavoidable``, ``unknown``, per sampler in ``samplers``), the first member's index (``first_index``), the
    parameter region they cover (``params``), their ``collision_types`` and the kinds of actor they were with
    (``with_kinds``); and from the cluster's conversion record (``conversion``, a
    :class:`~dv2s_gym.mining.conversion.record.ConversionRecord`; ``None`` when it was not converted): the failure
    ``video`` and the ``converted_video``, the ``status`` (a
    :class:`~dv2s_gym.mining.conversion.record.ConversionStatus` value, or ``"not converted"``) and its ``reason``,
    the ``bank_entry``, the entry it was ``merged_into``, the exact ``replay_entry`` and the parameters it could not
    narrow (``replay_not_narrowed``), the ``reproduction`` record and its ``reproduction_rate``, the ``e2e_sc``, the
    ``description`` and the ``script``. Every field is written, ``null`` when ``None``.
    """

    id: Optional[str] = None
    scenario: Optional[str] = None
    family: Optional[str] = None
    scenarios: Optional[Tuple[str, ...]] = None
    type: Optional[str] = None
    kind: Optional[str] = None
    region: Optional[str] = None
    behaviour: Optional[Behaviour] = None
    size: Optional[int] = None
    avoidable: Optional[int] = None
    unavoidable: Optional[int] = None
    unknown: Optional[int] = None
    samplers: Optional[Mapping[str, int]] = None
    first_index: Optional[int] = None
    params: Optional[Mapping[str, Any]] = None
    collision_types: Optional[Mapping[str, int]] = None
    with_kinds: Optional[Mapping[str, int]] = None
    representative: Optional[FailureEntry] = None
    video: Optional[str] = None
    converted_video: Optional[str] = None
    status: Optional[str] = None
    reason: Optional[str] = None
    bank_entry: Optional[str] = None
    merged_into: Optional[str] = None
    replay_entry: Optional[str] = None
    replay_not_narrowed: Optional[Mapping[str, Any]] = None
    reproduction: Optional[Any] = None
    reproduction_rate: Optional[float] = None
    e2e_sc: Optional[float] = None
    description: Optional[str] = None
    script: Optional[str] = None
    conversion: Optional[ConversionRecord] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"behaviour": "object"}
    _WHAT: ClassVar[str] = "cluster entry"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return _behaviour(data)

    def to_dict(self) -> Dict[str, Any]:
        return _behaviour_json(self, super().to_dict())


@dataclass(frozen=True, eq=False)
class RejectedConversion(JsonRecord):
    """A rejected conversion as the report lists it: its ``cluster`` and episode ``index``, the ``stage`` that
    rejected it, every failed check's reason (``rejections``) and those joined by ``"; "`` (``reason``)."""

    cluster: Optional[str] = None
    index: Optional[int] = None
    stage: Optional[str] = None
    reason: Optional[str] = None
    rejections: Tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "rejected conversion"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class EpisodeError(JsonRecord):
    """An episode that ended in an error: its ``index``, the ``sampler`` that drew it, its ``scenario``, env
    ``seed`` and the ``error``."""

    index: Optional[int] = None
    sampler: Optional[str] = None
    scenario: Optional[str] = None
    seed: Optional[int] = None
    error: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "episode error"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class WorkerRestart(JsonRecord):
    """An episode a new worker finished after its worker crashed or hung: its ``index``, ``scenario``, env
    ``seed`` and what happened to each earlier attempt (``problems``)."""

    index: Optional[int] = None
    scenario: Optional[str] = None
    seed: Optional[int] = None
    problems: Tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "worker restart"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class MineReport(JsonRecord):
    """A mining run's report (``report.json``, schema ``dv2s-mine-report``): when and by which version it was
    made, the run folder and its ``settings.json``, the ``counts`` (:class:`MineCounts`), each sampler's figures
    (``samplers``: :class:`SamplerSummary` by name), each scenario's (``scenarios``: :class:`ScenarioSummary` by
    name), the ``failure_rate`` under the scenarios' own distributions, the clusters (:class:`ClusterEntry`) and
    failures (:class:`FailureEntry`), each avoidable or unknown (``clusters``, ``failures``) and unavoidable
    (``unavoidable_clusters``, ``unavoidable``), the rejected conversions (:class:`RejectedConversion`), the
    episodes that ended in an error (:class:`EpisodeError`) or were finished by a new worker
    (:class:`WorkerRestart`), and the truncated lines left out (``skipped_lines``)."""

    schema: Optional[str] = None
    schema_version: Optional[int] = None
    created: Optional[str] = None
    dv2s_version: Optional[str] = None
    run_dir: Optional[str] = None
    settings: Mapping[str, Any] = field(default_factory=dict)
    counts: MineCounts = field(default_factory=MineCounts)
    samplers: Mapping[str, SamplerSummary] = field(default_factory=dict)
    scenarios: Mapping[str, ScenarioSummary] = field(default_factory=dict)
    failure_rate: Optional[Mapping[str, Any]] = None
    clusters: Tuple[ClusterEntry, ...] = ()
    unavoidable_clusters: Tuple[ClusterEntry, ...] = ()
    failures: Tuple[FailureEntry, ...] = ()
    unavoidable: Tuple[FailureEntry, ...] = ()
    rejected: Tuple[RejectedConversion, ...] = ()
    errors: Tuple[EpisodeError, ...] = ()
    worker_restarts: Tuple[WorkerRestart, ...] = ()
    skipped_lines: Mapping[str, int] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"dv2s_version": "any"}
    _WHAT: ClassVar[str] = "mining report"

    def default_null_fields(self) -> FrozenSet[str]:
        # every field of report.json is always written
        return self.json_fields()

    @property
    def policy(self) -> str:
        """The policy the run mined (``?`` when its settings do not name it)."""
        return str(self.settings.get("policy", "?"))


def mine_report(report: Any, function: str) -> MineReport:
    """``report`` when it is a :class:`MineReport`; otherwise a ``WrongTypeError`` naming ``function`` and what to
    pass (a ``report.json`` read as JSON is turned into one by :meth:`MineReport.from_dict`)."""
    if not isinstance(report, MineReport):
        raise WrongTypeError(f"{function} takes a MineReport, not {type(report).__name__}; read a report.json with "
                             "MineReport.from_dict(json.loads(text)) first")
    return report
