"""The typed mining report: :class:`MineReport`, the object ``report.json`` holds, as
:func:`dv2s_gym.mining.report.build_report` makes it and the report's renderings read it.

Its parts read by name are typed too: the run's ``counts`` (:class:`MineCounts`) and each sampler's figures
(:class:`SamplerSummary`). The clusters, failures, per-scenario rows, rejected conversions, errors and the failure
rate under the scenarios' own distributions stay JSON objects inside it (their schema is in the docstring of
:mod:`dv2s_gym.mining.report`; in process the clusters and failures are ``ClusterEntry`` and ``FailureEntry``
records and the rate a ``FailureRate``).

Each is a :class:`~scenario_bank.records.JsonRecord`: :meth:`from_dict` reads the JSON object (a
:class:`~scenario_bank.records.RecordError` names a field of the wrong kind, ``mining report field
'counts.failures'``), :meth:`to_dict` writes back exactly the object read (unknown keys kept in ``extra``, ``null``
where it was), so ``report.json`` is ``MineReport.to_dict()``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple

from scenario_bank.records import JsonRecord

__all__ = ["MineReport", "MineCounts", "SamplerSummary"]


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

    _KINDS: ClassVar[Dict[str, str]] = {
        "episodes": "int", "errors": "int", "worker_restarts": "int", "failures": "int", "failures_by_type": "object",
        "avoidable": "int", "unavoidable": "int", "avoidability_unknown": "int", "clusters": "int",
        "behaviours": "int", "scenario_failure_types": "int", "scenarios_failing": "int", "avoidable_clusters": "int",
        "unavoidable_clusters": "int", "converted": "int", "kept": "int", "merged": "int", "rejected": "int",
        "rejected_by_stage": "object", "conversion_seconds": "object", "conversion_stage_seconds": "object",
        "parameters_compared": "int", "parameters_not_compared": "int",
        "parameters_not_compared_by_reason": "object"}
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

    _KINDS: ClassVar[Dict[str, str]] = {
        "episodes": "int", "errors": "int", "failures": "int", "avoidable_failures": "int",
        "failures_per_100": "object", "avoidable_failures_per_100": "object", "clusters": "int",
        "avoidable_clusters": "int", "clusters_per_100": "number", "avoidable_clusters_per_100": "number",
        "episodes_to_first_failure": "int", "discovery": "list"}
    _LISTS: ClassVar[Tuple[str, ...]] = ("discovery",)
    _WHAT: ClassVar[str] = "sampler summary"


@dataclass(frozen=True, eq=False)
class MineReport(JsonRecord):
    """A mining run's report (``report.json``, schema ``dv2s-mine-report``): when and by which version it was
    made, the run folder and its ``settings.json``, the ``counts`` (:class:`MineCounts`), each sampler's figures
    (``samplers``: :class:`SamplerSummary` by name), each scenario's (``scenarios``), the ``failure_rate`` under the
    scenarios' own distributions, the clusters and failures (avoidable or unknown, and unavoidable), the rejected
    conversions, the episodes that ended in an error or were finished by a new worker, and the truncated lines
    left out (``skipped_lines``)."""

    schema: Optional[str] = None
    schema_version: Optional[int] = None
    created: Optional[str] = None
    dv2s_version: Optional[str] = None
    run_dir: Optional[str] = None
    settings: Mapping[str, Any] = field(default_factory=dict)
    counts: MineCounts = field(default_factory=MineCounts)
    samplers: Mapping[str, SamplerSummary] = field(default_factory=dict)
    scenarios: Mapping[str, Any] = field(default_factory=dict)
    failure_rate: Optional[Mapping[str, Any]] = None
    clusters: Tuple[Mapping[str, Any], ...] = ()
    unavoidable_clusters: Tuple[Mapping[str, Any], ...] = ()
    failures: Tuple[Mapping[str, Any], ...] = ()
    unavoidable: Tuple[Mapping[str, Any], ...] = ()
    rejected: Tuple[Mapping[str, Any], ...] = ()
    errors: Tuple[Mapping[str, Any], ...] = ()
    worker_restarts: Tuple[Mapping[str, Any], ...] = ()
    skipped_lines: Mapping[str, int] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {
        "schema": "str", "schema_version": "int", "created": "str", "dv2s_version": "any", "run_dir": "str",
        "settings": "object", "counts": "object", "samplers": "object", "scenarios": "object",
        "failure_rate": "object", "clusters": "objects", "unavoidable_clusters": "objects", "failures": "objects",
        "unavoidable": "objects", "rejected": "objects", "errors": "objects", "worker_restarts": "objects",
        "skipped_lines": "object"}
    _NESTED: ClassVar[Dict[str, type]] = {"counts": MineCounts}
    _ITEMS: ClassVar[Dict[str, type]] = {"samplers": SamplerSummary}
    _LISTS: ClassVar[Tuple[str, ...]] = ("clusters", "unavoidable_clusters", "failures", "unavoidable", "rejected",
                                         "errors", "worker_restarts")
    _WHAT: ClassVar[str] = "mining report"

    def default_null_fields(self) -> FrozenSet[str]:
        # every field of report.json is always written
        return frozenset(self._KINDS)

    @property
    def policy(self) -> str:
        """The policy the run mined (``?`` when its settings do not name it)."""
        return str(self.settings.get("policy", "?"))
