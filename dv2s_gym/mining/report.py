"""The mining report: what a ``dv2s mine`` run found, read back from its run folder.

:func:`build_report` reads a run folder (``settings.json``, ``episodes.jsonl`` as
:class:`~scenario_bank.records.EpisodeRecord`, ``conversions.jsonl`` as
:class:`~dv2s_gym.mining.conversion.record.ConversionRecord`; record formats in the mining contract), groups
the failures into clusters with :func:`dv2s_gym.mining.cluster.cluster_failures` and returns the report as a
:class:`~dv2s_gym.mining.report_record.MineReport`, whose ``to_dict`` is the JSON below (its clusters are
:class:`~dv2s_gym.mining.report_record.ClusterEntry` records, its failures
:class:`~dv2s_gym.mining.report_record.FailureEntry` records, and so on: :mod:`dv2s_gym.mining.report_record`);
:func:`headline`, :func:`format_summary`, :func:`markdown` and the page take the record only (read a ``report.json``
with ``MineReport.from_dict``); :func:`write_reports` writes it as ``report.json`` (atomic), ``report.md`` and the
self-contained ``report.html`` (:mod:`dv2s_gym.mining.html`). Nothing here imports Scenic
or highway-env, so a report is rebuilt in well under a second from any run folder, also
from one whose run was killed (a truncated last line of a ``.jsonl`` file is left out).

JSON schema ``dv2s-mine-report``, version 3 (:data:`SCHEMA_VERSION`; a change to any key bumps it)::

    {
      "schema": "dv2s-mine-report", "schema_version": 3, "created": ISO-8601 (UTC), "dv2s_version",
      "run_dir": the run folder, "settings": settings.json as written by the miner,
      "counts": {
        "episodes": finished episodes without an error, "errors": episodes that ended in an error,
        "worker_restarts": episodes finished by a new worker after theirs crashed or hung,
        "failures": episodes with a failure, "failures_by_type": {type: n}, "collisions", "stalls": failures of a
        type that is the ego touching an actor / standing (zero included),
        "avoidable": failures the reference driver avoided in the same scene (they count against the policy),
        "unavoidable": failures the reference driver had too, "avoidability_unknown": no reference outcome,
        "clusters": distinct clusters (behaviours, :mod:`dv2s_gym.mining.cluster`), "behaviours": the same count,
        "scenario_failure_types": distinct (scenario family, failure class) pairs, "scenarios_failing": scenario
        families with a failure (a family: :mod:`dv2s_gym.mining.family`),
        "avoidable_clusters": clusters with an avoidable failure,
        "unavoidable_clusters": clusters whose failures are all unavoidable,
        "converted": conversion records (one per converted cluster representative),
        "kept", "merged", "rejected": by conversion status, "rejected_by_stage": {stage: n},
        "conversion_seconds": {"n", "median", "max", "total"},
        "conversion_stage_seconds": {stage: median seconds} (from the conversions' ``timings``),
        "parameters_compared", "parameters_not_compared": failing parameter values the conversion judge compared
        with the new scripts' ranges, and those it could not compare, "parameters_not_compared_by_reason": {reason:
        n} of those (:data:`dv2s_gym.mining.report_text.NOT_COMPARED_REASONS`)},
      "samplers": {name: Sampler},
      "scenarios": {name: Scenario},
      "failure_rate": {"available", "reason", "overall": Estimate, "scenarios": {name: Estimate}}
                                          the failure rate under the scenarios' own parameter distributions
                                          (:mod:`dv2s_gym.mining.sampling.rate`),
      "clusters": [Cluster]               clusters with at least one failure not known to be unavoidable,
      "unavoidable_clusters": [Cluster]   clusters whose failures the reference driver had too,
      "failures": [Failure]               failures not known to be unavoidable (avoidable or unknown),
      "unavoidable": [Failure]            unavoidable failures, with the reference driver's outcome,
      "rejected": [{"cluster", "index", "stage", "reason": every failed check's reason, "; "-joined,
                    "rejections": those reasons}],
      "errors": [{"index", "sampler", "scenario", "seed", "error"}],
      "worker_restarts": [{"index", "scenario", "seed", "problems": [what happened to each earlier attempt]}],
      "skipped_lines": {file: n}          truncated last lines left out (a run killed mid-write)
    }

``Sampler``: ``{"episodes", "errors", "failures", "avoidable_failures",
"failures_per_100" and "avoidable_failures_per_100": {"value", "low", "high", "count", "n"}``
(per 100 episodes, Wilson 95 % interval), ``"clusters", "avoidable_clusters",
"clusters_per_100", "avoidable_clusters_per_100", "episodes_to_first_failure",
"discovery": [[episodes, distinct clusters], ...]}`` (a point where each new cluster was
found, and the last episode). An adaptive sampler's episodes are not independent draws,
so its interval is a guide, not an exact guarantee.

``Scenario``: ``{"episodes", "errors", "failures", "avoidable", "unavoidable", "unknown",
"failure_rate": {"value", "low", "high", "count"} (Wilson 95 %, as sampled), "estimated_rate": Estimate | null
(under the scenario's own parameter distribution), "failures_by_type", "failure_types",
"clusters", "avoidable_clusters", "converted", "kept"}``.

``Estimate``: ``{"value" (capped at 1), "raw" (the importance-sampling estimate itself), "low", "high" (95 %), "ess"
(effective sample size), "n", "failures"}``.

``Cluster``: ``{"id", "scenario" (its representative's), "family" (the first part of the id),
"scenarios" (every scenario its failures ran in), "type", "kind", "region" (the id after family and class), "behaviour":
{"actor", "actor_manoeuvre", "ego_manoeuvre"}, "size", "avoidable", "unavoidable",
"unknown", "samplers": {name: n}, "first_index", "params": {name: {"min", "max"} |
{"values"}}`` (the parameter region its failures cover), ``"collision_types", "with_kinds",
"representative": Failure, "video": path relative to the run folder | null, "converted_video": the clip of the
converted script driven by the policy (one reproduction episode; ``reproduction["clip"]`` says which) | null, "status":
"kept" | "merged" | "rejected" | "not converted", "reason", "bank_entry", "merged_into", "replay_entry": the
exact replay entry the conversion kept | null, "replay_not_narrowed": ``{parameter: why}`` of those its replay
draws as the parent does ({} when every one was narrowed, or without a replay entry),
"reproduction": the conversion's record | null, "reproduction_rate", "e2e_sc", "description",
"script", "conversion": the conversion record | null}``. A conversion belongs to the cluster
of its representative episode (``index``); its own ``cluster`` id is kept in the record.

``Failure``: ``{"index", "sampler", "scenario", "family", "seed", "params", "type", "kind" (the type refined by the
collision type, e.g. ``collision:rear_end``), "time", "with",
"with_kind", "collision_type", "min_ttc", "rho", "avoidable", "reference", "cluster", "behaviour",
"trace"}``; replay one exactly with ``dv2s replay RUN/TRACE``.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import statistics
from collections import Counter
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from dv2s_gym.mining.cluster import cluster_failures
from dv2s_gym.mining.conversion.record import ConversionRecord, ConversionStatus
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.html import write_html
from dv2s_gym.mining.sampling.rate import FailureRate, rate_estimates
from dv2s_gym.mining.report_record import (ClusterEntry, EpisodeError, FailureEntry, mine_report, MineReport,
                                           RejectedConversion, ScenarioSummary, WorkerRestart)
from dv2s_gym.mining.report_text import (NOT_COMPARED_REASONS, breadth, by_type_text, error_warning,
                                         not_compared_counts, parameter_check_text, rate_text, replaced_in,
                                         replaced_text, seed_text)
from dv2s_gym.mining.report_text import number_text as _num
from dv2s_gym.mining.settings import read_run_settings, RunSettings, SETTINGS_FILE
from dv2s_gym.mining.report_text import percent_text as _pct
from policies.run_identity import installed_version
from policies.stats import Rate
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.failure_types import FAILURE_TYPES, is_contact, is_standstill, severity_order
from scenario_bank.records import EpisodeRecord, RecordError

__all__ = [
    "SCHEMA", "SCHEMA_VERSION", "FAILURE_ORDER", "MiningReportError", "read_jsonl", "read_run",
    "build_report", "build_report_from_records", "format_summary", "markdown", "write_reports", "breadth", "rate_text",
]

SCHEMA = "dv2s-mine-report"
SCHEMA_VERSION = 3
CONFIDENCE = 0.95
FAILURE_ORDER = FAILURE_TYPES
"""Failure types in the order the report lists them (other types follow, sorted):
:data:`scenario_bank.failure_types.FAILURE_TYPES`."""
STATUS_ORDER = (ConversionStatus.KEPT, ConversionStatus.MERGED, ConversionStatus.REJECTED)
NOT_CONVERTED = "not converted"

PathLike = Union[str, os.PathLike]


class MiningReportError(MiningError):
    """A run folder that cannot be reported on (missing, not a mining run, unreadable records)."""


# --------------------------------------------------------------------------------- reading
def read_jsonl(path: PathLike) -> Tuple[List[Dict[str, Any]], int]:
    """The JSON objects of a ``.jsonl`` file and how many truncated last lines were left out.

    A missing file holds no records. An unreadable last line (a run killed while appending)
    is left out and counted; an unreadable line anywhere else raises
    :class:`MiningReportError` naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        return [], 0
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    records: List[Dict[str, Any]] = []
    skipped = 0
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError as error:
            if number == len(lines):
                skipped += 1
                continue
            raise MiningReportError(f"{path}:{number} is not a JSON record ({error}); the file is damaged: "
                                    "remove that line (its episode is run again on resume) and rebuild the report"
                                    ) from None
        if not isinstance(record, dict):
            raise MiningReportError(f"{path}:{number} is a JSON {type(record).__name__}, not a record object; "
                                    "remove that line and rebuild the report")
        records.append(record)
    return records, skipped


def read_run(run_dir: PathLike) -> Tuple[RunSettings, List[EpisodeRecord], List[ConversionRecord], Dict[str, int]]:
    """``(settings, episodes, conversions, skipped_lines)`` of a run folder (``settings``: its ``settings.json``,
    :func:`~dv2s_gym.mining.settings.read_run_settings`; ``episodes``: its episode records; ``conversions``: its
    conversion records).

    Episodes are sorted by index, one per index (the first record of an index wins);
    conversions keep the last record of each cluster id.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise MiningReportError(f"run folder {run_dir} does not exist; give the --out folder of a `dv2s mine` run")
    settings = read_run_settings(run_dir, error=MiningReportError)
    if settings is None:
        raise MiningReportError(f"{run_dir} has no {SETTINGS_FILE}, so it is not a `dv2s mine` run folder; give the "
                                "--out folder of a mining run")
    episodes, skipped_episodes = read_jsonl(run_dir / "episodes.jsonl")
    conversions, skipped_conversions = read_jsonl(run_dir / "conversions.jsonl")
    by_index: Dict[int, EpisodeRecord] = {}
    for number, row in enumerate(episodes, 1):
        try:
            index = int(row["index"])
        except (KeyError, TypeError, ValueError):
            raise MiningReportError(f"{run_dir / 'episodes.jsonl'}: record {number} has no integer 'index'; "
                                    "remove it and rebuild the report") from None
        if index not in by_index:
            try:
                by_index[index] = EpisodeRecord.from_dict(row)
            except RecordError as error:
                raise MiningReportError(f"{run_dir / 'episodes.jsonl'}: record {number}: {error}; remove it and "
                                        "rebuild the report") from None
    latest: Dict[str, ConversionRecord] = {}
    for number, row in enumerate(conversions, 1):
        try:
            record = ConversionRecord.from_dict(row)
        except RecordError as error:
            raise MiningReportError(f"{run_dir / 'conversions.jsonl'}: record {number}: {error}; remove it and "
                                    "rebuild the report") from None
        latest[str(record.cluster)] = record
    skipped = {name: n for name, n in (("episodes.jsonl", skipped_episodes),
                                       ("conversions.jsonl", skipped_conversions)) if n}
    ordered = [by_index[i] for i in sorted(by_index)]
    return settings, ordered, list(latest.values()), skipped


# ------------------------------------------------------------------------------- helpers
def _clean(value: Any) -> Any:
    """JSON-safe: non-finite floats become ``None``, tuples lists, keys strings."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def _by_type(failures: Sequence["FailureEntry"]) -> Dict[str, int]:
    counts = Counter(str(f.type) for f in failures)
    return {t: counts[t] for t in severity_order(counts)}


def _stage(reason: Any) -> str:
    """The stage a rejection reason names (``"stage: message"``), or ``"unknown"`` (for records without ``stage``)."""
    text = str(reason or "").strip()
    if ":" in text:
        stage = text.split(":", 1)[0].strip()
        if stage and len(stage) <= 40:
            return stage
    return "unknown"


def _param_region(members: Sequence["FailureEntry"]) -> Dict[str, Any]:
    """Per parameter: ``{"min", "max"}`` over the members' numeric values, else ``{"values"}``."""
    values: Dict[str, List[Any]] = {}
    for member in members:
        for name, value in member.params.items():
            values.setdefault(str(name), []).append(value)
    region: Dict[str, Any] = {}
    for name in sorted(values):
        numbers = [float(v) for v in values[name] if isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(float(v))]
        if len(numbers) == len(values[name]):
            region[name] = {"min": min(numbers), "max": max(numbers)}
        else:
            region[name] = {"values": sorted({json.dumps(v, sort_keys=True, default=str) for v in values[name]})}
    return region


def _representative(members: Sequence[FailureEntry], conversion: Optional[ConversionRecord]) -> FailureEntry:
    """The converted episode, else the one the miner would convert: among failures not known to be
    unavoidable (all, when every one is), the most violated (lowest rho), then the first."""
    if conversion is not None:
        for member in members:
            if member.index == conversion.index:
                return member
    pool = [m for m in members if m.avoidable is not False] or list(members)

    def key(member: FailureEntry) -> Tuple[float, int]:
        rho = member.rho
        rho = float(rho) if isinstance(rho, (int, float)) and math.isfinite(float(rho)) else 0.0
        return rho, member.index

    return min(pool, key=key)


def _cluster_of(records: Sequence[EpisodeRecord]) -> Dict[int, str]:
    """Cluster id of every failed episode, from the mining core's clustering."""
    mapping = cluster_failures(list(records))
    return {int(index): str(cluster) for index, cluster in dict(mapping).items()}


# --------------------------------------------------------------------------------- report
def build_report(run_dir: PathLike, *, created: Optional[str] = None) -> MineReport:
    """The report (:class:`~dv2s_gym.mining.report_record.MineReport`; schema in the module docstring) of the run
    folder ``run_dir``.

    Raises :class:`MiningReportError` for a folder that is not a mining run or holds
    damaged records.
    """
    settings, episodes, conversions, skipped = read_run(run_dir)
    failed = [r for r in episodes if r.failed]
    clusters = _cluster_of(episodes) if failed else {}
    report = build_report_from_records(settings.values, episodes, conversions, clusters, created=created)
    return report.replace(run_dir=str(run_dir), skipped_lines=dict(skipped))


def _episode_errors(episodes: Sequence[EpisodeRecord], default_sampler: str) -> List[EpisodeError]:
    """The episodes that errored: index, sampler, scenario, seed and the error."""
    return [EpisodeError(index=int(r.index), sampler=str(r.sampler or default_sampler), scenario=r.scenario,
                         seed=r.seed, error=str(r.error))
            for r in episodes if r.error]


def _worker_restarts(episodes: Sequence[EpisodeRecord]) -> List[WorkerRestart]:
    """The episodes a new worker finished (their worker crashed or hung), with what happened to it."""
    return [WorkerRestart(index=int(r.index), scenario=r.scenario, seed=r.seed,
                          problems=tuple(str(p) for p in r.worker_restarts)) for r in episodes if r.worker_restarts]


def _failures(ok: Sequence[EpisodeRecord], clusters: Mapping[int, str], default_sampler: str) -> List[FailureEntry]:
    """An entry for each failed episode of those that ran, with its cluster id.

    Raises :class:`MiningReportError` when a failed episode has no cluster id.
    """
    failed = [r for r in ok if r.failure]
    missing = [int(r.index) for r in failed if int(r.index) not in clusters]
    if missing:
        raise MiningReportError(f"the clustering gave no cluster to failed episode(s) {missing[:10]}; "
                                "this is a bug in dv2s_gym.mining.cluster.cluster_failures, please report it")
    return [FailureEntry.of(r, clusters[int(r.index)], default_sampler) for r in failed]


def _conversions_by_cluster(conversions: Sequence[ConversionRecord],
                            clusters: Mapping[int, str]) -> Dict[str, List[ConversionRecord]]:
    """The conversions, attached to the cluster of their representative episode."""
    by_cluster: Dict[str, List[ConversionRecord]] = {}
    for conversion in conversions:
        index = conversion.index
        cluster = clusters.get(int(index)) if isinstance(index, int) else None
        cluster = cluster or str(conversion.cluster)
        by_cluster.setdefault(cluster, []).append(conversion)
    return by_cluster


def _primary_conversion(found: Sequence[ConversionRecord]) -> Optional[ConversionRecord]:
    """The conversion of a cluster that counts: kept before merged before rejected, else the first."""
    status_rank = {s: i for i, s in enumerate(STATUS_ORDER)}
    return min(found, key=lambda c: status_rank.get(c.status, len(STATUS_ORDER))) if found else None


def _cluster_entry(cluster_id: str, members: Sequence[FailureEntry],
                   conversion: Optional[ConversionRecord]) -> ClusterEntry:
    """A cluster's entry: its representative, its members' counts and parameter region, and its conversion."""
    representative = _representative(members, conversion)
    parts = cluster_id.split("/", 2)
    found = conversion if conversion is not None else ConversionRecord()
    reproduction = found.reproduction
    return ClusterEntry(
        id=cluster_id, scenario=representative.scenario, family=representative.family,
        scenarios=tuple(sorted({str(m.scenario) for m in members})), type=representative.type,
        kind=parts[1] if len(parts) == 3 else representative.kind, region=parts[2] if len(parts) == 3 else cluster_id,
        behaviour=representative.behaviour, size=len(members),
        avoidable=sum(m.avoidable is True for m in members), unavoidable=sum(m.avoidable is False for m in members),
        unknown=sum(m.avoidable is None for m in members),
        samplers=dict(sorted(Counter(m.sampler for m in members).items())),
        first_index=min(m.index for m in members), params=_param_region(members),
        collision_types=dict(sorted(Counter(str(m.collision_type) for m in members if m.collision_type).items())),
        with_kinds=dict(sorted(Counter(str(m.with_kind) for m in members if m.with_kind).items())),
        representative=representative, video=found.video, converted_video=found.converted_video,
        status=found.status.value if found.status else NOT_CONVERTED, reason=found.reason,
        bank_entry=found.bank_entry, merged_into=found.merged_into, replay_entry=found.replay_entry,
        replay_not_narrowed=dict(found.replay_not_narrowed or {}), reproduction=reproduction,
        reproduction_rate=(reproduction or {}).get("rate") if isinstance(reproduction, Mapping) else None,
        e2e_sc=found.e2e_sc, description=found.description, script=found.script, conversion=conversion)


def _cluster_entries(failures: Sequence[FailureEntry], conversions: Sequence[ConversionRecord],
                     clusters: Mapping[int, str]) -> List[ClusterEntry]:
    """Every cluster's entry, the most avoidable failures first, then the largest, then the first found."""
    by_cluster_conversions = _conversions_by_cluster(conversions, clusters)
    members_of: Dict[str, List[FailureEntry]] = {}
    for failure in failures:
        members_of.setdefault(failure.cluster, []).append(failure)
    entries = [_cluster_entry(cluster_id, members, _primary_conversion(by_cluster_conversions.get(cluster_id) or []))
               for cluster_id, members in members_of.items()]
    entries.sort(key=lambda c: (-c.avoidable, -c.size, c.first_index))
    return entries


def _rejected_conversions(conversions: Sequence[ConversionRecord]) -> List[RejectedConversion]:
    """The rejected conversions: every check the judge failed is a reason of its own (``rejections``; the first
    is ``reason``)."""
    return [RejectedConversion(cluster=c.cluster, index=c.index, stage=c.stage or _stage(c.reason),
                               reason="; ".join(c.rejections or []) or c.reason,
                               rejections=tuple(c.rejections or ([c.reason] if c.reason else [])))
            for c in conversions if c.status == ConversionStatus.REJECTED]


def _failure_counts(ok: Sequence[EpisodeRecord], errors: Sequence[EpisodeError],
                    restarts: Sequence[WorkerRestart], failures: Sequence[FailureEntry],
                    cluster_entries: Sequence[ClusterEntry]) -> Dict[str, Any]:
    """The counts of episodes, failures and clusters."""
    return {
        "episodes": len(ok),
        "errors": len(errors),
        "worker_restarts": len(restarts),
        "failures": len(failures),
        "failures_by_type": _by_type(failures),
        "collisions": sum(is_contact(str(f.type)) for f in failures),
        "stalls": sum(is_standstill(str(f.type)) for f in failures),
        "avoidable": sum(f.avoidable is True for f in failures),
        "unavoidable": sum(f.avoidable is False for f in failures),
        "avoidability_unknown": sum(f.avoidable is None for f in failures),
        "clusters": len(cluster_entries),
        "behaviours": len(cluster_entries),
        "scenario_failure_types": len({(f.family, str(f.kind)) for f in failures}),
        "scenarios_failing": len({f.family for f in failures}),
        "avoidable_clusters": sum(c.avoidable > 0 for c in cluster_entries),
        "unavoidable_clusters": len({c.id for c in cluster_entries if c.unavoidable == c.size}),
    }


def _conversion_counts(conversions: Sequence[ConversionRecord],
                       rejected: Sequence[RejectedConversion]) -> Dict[str, Any]:
    """The counts of conversions by status and stage, their times, and the judge's parameter check."""
    statuses = Counter(c.status for c in conversions)
    seconds = [float(c.seconds) for c in conversions
               if isinstance(c.seconds, (int, float)) and math.isfinite(float(c.seconds))]
    stage_seconds: Dict[str, List[float]] = {}
    for conversion in conversions:
        for stage, value in (conversion.timings or {}).items():
            if isinstance(value, (int, float)) and math.isfinite(float(value)):
                stage_seconds.setdefault(str(stage), []).append(float(value))
    not_compared: Dict[str, int] = {}
    for c in conversions:
        parameters = c.parameters or {}
        for key, n in not_compared_counts(parameters.get("not_comparable")).items():
            not_compared[key] = not_compared.get(key, 0) + n
    not_compared = {key: not_compared[key] for key, _, _ in NOT_COMPARED_REASONS if key in not_compared}
    return {
        "converted": len(conversions),
        "kept": statuses[ConversionStatus.KEPT],
        "merged": statuses[ConversionStatus.MERGED],
        "rejected": statuses[ConversionStatus.REJECTED],
        "rejected_by_stage": dict(sorted(Counter(r.stage for r in rejected).items())),
        "conversion_seconds": {"n": len(seconds), "median": statistics.median(seconds) if seconds else None,
                               "max": max(seconds) if seconds else None, "total": sum(seconds)},
        "conversion_stage_seconds": {stage: statistics.median(values) for stage, values in stage_seconds.items()},
        # the judge's parameter check: failing parameters compared with the new script's ranges, and not
        "parameters_compared": sum(len((c.parameters or {}).get("compared") or {}) for c in conversions),
        "parameters_not_compared": sum(not_compared.values()),
        "parameters_not_compared_by_reason": not_compared,
    }


def _sampler_entry(mine: Sequence[EpisodeRecord], found: Sequence[FailureEntry],
                   clusters: Mapping[int, str]) -> Dict[str, Any]:
    """One sampler's episodes (``mine``) and failures (``found``): rates per 100 episodes and its discovery curve
    (``[episode, distinct clusters so far]`` at each new cluster and at the last episode)."""
    ran = [r for r in mine if not r.error]
    avoidable = [f for f in found if f.avoidable is True]
    seen: set = set()
    discovery: List[List[int]] = []
    first_failure = None
    for position, record in enumerate(ran, 1):
        if record.failure:
            first_failure = first_failure or position
            cluster = clusters[int(record.index)]
            if cluster not in seen:
                seen.add(cluster)
                discovery.append([position, len(seen)])
    if ran and (not discovery or discovery[-1][0] != len(ran)):
        discovery.append([len(ran), len(seen)])
    n = len(ran)
    distinct = len({f.cluster for f in found})
    distinct_avoidable = len({f.cluster for f in avoidable})
    return {
        "episodes": n,
        "errors": len(mine) - n,
        "failures": len(found),
        "avoidable_failures": len(avoidable),
        "failures_per_100": Rate.of(len(found), n, CONFIDENCE).report_json(scale=100.0, with_n=True),
        "avoidable_failures_per_100": Rate.of(len(avoidable), n, CONFIDENCE).report_json(scale=100.0,
                                                                                             with_n=True),
        "clusters": distinct,
        "avoidable_clusters": distinct_avoidable,
        "clusters_per_100": 100.0 * distinct / n if n else None,
        "avoidable_clusters_per_100": 100.0 * distinct_avoidable / n if n else None,
        "episodes_to_first_failure": first_failure,
        "discovery": discovery,
    }


def _per_sampler(episodes: Sequence[EpisodeRecord], failures: Sequence[FailureEntry],
                 clusters: Mapping[int, str], default_sampler: str) -> Dict[str, Any]:
    """:func:`_sampler_entry` of every sampler that drew episodes (and of the run's own sampler), by name."""
    names = sorted({str(r.sampler or default_sampler) for r in episodes} | {default_sampler})
    return {name: _sampler_entry([r for r in episodes if str(r.sampler or default_sampler) == name],
                                 [f for f in failures if f.sampler == name], clusters)
            for name in names}


def _per_scenario(settings: Mapping[str, Any], episodes: Sequence[EpisodeRecord],
                  errors: Sequence[EpisodeError], failures: Sequence[FailureEntry],
                  cluster_entries: Sequence[ClusterEntry], rate: FailureRate) -> Dict[str, ScenarioSummary]:
    """Per scenario (the run's own, then any other an episode ran): its episodes, failures, failure rates (sampled
    and estimated), clusters and conversions."""
    ok = [r for r in episodes if not r.error]
    scenario_names = list(dict.fromkeys([*(settings.get("scenarios") or []),
                                         *sorted({str(r.scenario) for r in episodes})]))
    scenarios: Dict[str, ScenarioSummary] = {}
    for name in scenario_names:
        ran = [r for r in ok if str(r.scenario) == name]
        found = [f for f in failures if str(f.scenario) == name]
        in_clusters = [c for c in cluster_entries if name in c.scenarios]
        scenarios[name] = ScenarioSummary(
            episodes=len(ran), errors=sum(1 for e in errors if str(e.scenario) == name), failures=len(found),
            avoidable=sum(f.avoidable is True for f in found), unavoidable=sum(f.avoidable is False for f in found),
            unknown=sum(f.avoidable is None for f in found),
            failure_rate=Rate.of(len(found), len(ran), CONFIDENCE).report_json(),
            estimated_rate=rate.scenarios[name].to_dict() if name in rate.scenarios else None,
            failures_by_type=_by_type(found), failure_types=len({str(f.kind) for f in found}),
            clusters=len(in_clusters), avoidable_clusters=sum(c.avoidable > 0 for c in in_clusters),
            converted=sum(c.conversion is not None for c in in_clusters),
            kept=sum(c.status == ConversionStatus.KEPT for c in in_clusters))
    return scenarios


def build_report_from_records(settings: Mapping[str, Any], episodes: Sequence[EpisodeRecord],
                              conversions: Sequence[ConversionRecord], clusters: Mapping[int, str], *,
                              created: Optional[str] = None) -> MineReport:
    """The report (:class:`~dv2s_gym.mining.report_record.MineReport`) from records already read: ``settings`` (the
    run's ``settings.json``), its episode records, its conversion records
    (:class:`~dv2s_gym.mining.conversion.record.ConversionRecord`), and ``clusters``, which maps each failed episode's
    index to its cluster id.

    Raises :class:`MiningReportError` when a failed episode has no cluster id.
    """
    default_sampler = str(settings.get("sampler") or "unknown")
    conversions = [ConversionRecord.from_dict(c) for c in conversions]  # given as records or their JSON objects
    episodes = sorted(episodes, key=lambda r: int(r.index))
    ok = [r for r in episodes if not r.error]
    errors = _episode_errors(episodes, default_sampler)
    restarts = _worker_restarts(episodes)
    failures = _failures(ok, clusters, default_sampler)
    cluster_entries = _cluster_entries(failures, conversions, clusters)
    unavoidable_ids = {c.id for c in cluster_entries if c.unavoidable == c.size}
    rejected = _rejected_conversions(conversions)
    counts = {**_failure_counts(ok, errors, restarts, failures, cluster_entries),
              **_conversion_counts(conversions, rejected)}
    samplers = _per_sampler(episodes, failures, clusters, default_sampler)
    rate = rate_estimates(settings, episodes)  # errored episodes are left out of the rate, counted as drawn
    scenarios = _per_scenario(settings, episodes, errors, failures, cluster_entries, rate)
    report = {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "created": created or datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "dv2s_version": installed_version(),
        "run_dir": None,
        "settings": dict(settings),
        "counts": counts,
        "samplers": samplers,
        "scenarios": {name: entry.to_dict() for name, entry in scenarios.items()},
        "failure_rate": rate.to_dict(),
        "clusters": [c.to_dict() for c in cluster_entries if c.id not in unavoidable_ids],
        "unavoidable_clusters": [c.to_dict() for c in cluster_entries if c.id in unavoidable_ids],
        "failures": [f.to_dict() for f in failures if f.avoidable is not False],
        "unavoidable": [f.to_dict() for f in failures if f.avoidable is False],
        "rejected": [r.to_dict() for r in rejected],
        "errors": [e.to_dict() for e in errors],
        "worker_restarts": [r.to_dict() for r in restarts],
        "skipped_lines": {},
    }
    return MineReport.from_dict(_clean(report))



# ----------------------------------------------------------------------------------- text
def _per_100_text(entry: Optional[Mapping[str, Any]]) -> str:
    if not entry or entry.get("value") is None:
        return "-"
    return f"{entry['value']:.1f} [{entry['low']:.1f}, {entry['high']:.1f}]"


def _region_text(params: Mapping[str, Any], limit: int = 4) -> str:
    parts = []
    for name, region in list(params.items())[:limit]:
        if "min" in region:
            low, high = region["min"], region["max"]
            parts.append(f"{name} {low:.3g}" if low == high else f"{name} {low:.3g}..{high:.3g}")
        else:
            parts.append(f"{name} in {{{', '.join(region['values'][:3])}}}")
    if len(params) > limit:
        parts.append(f"+{len(params) - limit} more")
    return ", ".join(parts) or "-"


def _reproduction_text(cluster: ClusterEntry) -> str:
    reproduction = cluster.reproduction
    if not isinstance(reproduction, Mapping) or reproduction.get("rate") is None:
        return "-"
    text = f"{reproduction['rate']:.2f}"
    if reproduction.get("k") is not None:
        text += f" ({reproduction.get('reproduced', '?')}/{reproduction['k']})"
    interval = reproduction.get("interval")
    if isinstance(interval, (list, tuple)) and len(interval) == 2 and None not in interval:
        text += f" [{interval[0]:.2f}, {interval[1]:.2f}]"
    return text


def _cell(value: Any) -> str:
    """A Markdown table cell: one line, pipes escaped."""
    return str("-" if value is None else value).replace("\n", " ").replace("|", "\\|")


def headline(report: MineReport) -> str:
    """One line: what was mined and what came of it."""
    report = mine_report(report, "headline")
    counts, settings = report.counts, report.settings
    return (f"policy `{settings.get('policy')}`, sampler {settings.get('sampler')}, {seed_text(settings)}: "
            f"{counts.failures} failure(s) in {counts.episodes} episode(s) "
            f"({counts.avoidable} avoidable, {counts.unavoidable} unavoidable, "
            f"{counts.avoidability_unknown} unknown), {counts.clusters} distinct behaviour(s) "
            f"({counts.avoidable_clusters} avoidable); converted {counts.converted}: kept {counts.kept}, "
            f"merged {counts.merged}, rejected {counts.rejected}"
            + (f"; {counts.errors} error(s)" if counts.errors else "")
            + (f". {_error_alarm(report)}" if counts.errors else "")
            + (f". {replaced_text(replaced_in(settings))}" if replaced_in(settings) else ""))


def _error_alarm(report: MineReport) -> str:
    errors = report.errors
    first = str(errors[0].error or "").strip().splitlines() if errors else []
    counts = report.counts
    return error_warning(counts.errors, counts.errors + counts.episodes, first[-1] if first else "")


def format_summary(report: MineReport) -> str:
    """The plain-text summary ``dv2s mine`` prints: the headline and the per-sampler table."""
    report = mine_report(report, "format_summary")
    rows = [("sampler", "episodes", "failures", "per 100 [95% CI]", "avoidable per 100", "clusters",
             "clusters per 100")]
    for name, entry in report.samplers.items():
        rows.append((name, str(entry.episodes), str(entry.failures), _per_100_text(entry.failures_per_100),
                     _per_100_text(entry.avoidable_failures_per_100), str(entry.clusters),
                     _num(entry.clusters_per_100)))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [headline(report).replace("`", ""), breadth(report.counts), rate_text(report.failure_rate)]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    if report.rejected:
        lines.append("rejected: " + "; ".join(f"{r.cluster} ({r.reason})" for r in report.rejected[:3])
                     + (" ..." if len(report.rejected) > 3 else ""))
    return "\n".join(lines)


def _type_text(cluster: ClusterEntry) -> str:
    """The cluster's failure type with how and with whom, e.g. ``collision (rear_end, with car)``."""
    details = list(cluster.collision_types or {}) + [f"with {kind}" for kind in cluster.with_kinds or {}]
    return f"{cluster.type} ({', '.join(details)})" if details else str(cluster.type)


def _cluster_rows(clusters: Sequence[ClusterEntry]) -> List[str]:
    lines = ["| cluster | scenario | type | failures | avoidable | parameter region | representative | status | "
             "bank entry | reproduction | E2E-SC |",
             "|---|---|---|---:|---:|---|---|---|---|---|---:|"]
    for c in clusters:
        rep = c.representative
        status = c.status + (f" into `{c.merged_into}`" if c.merged_into else "")
        video = f" [video]({c.video})" if c.video else ""
        entries = ", ".join(f"`{_cell(name)}`" for name in c.scenarios or [c.scenario])
        lines.append(f"| `{_cell(c.id)}` | {entries} | {_cell(_type_text(c))} | {c.size} | "
                     f"{c.avoidable} | {_cell(_region_text(c.params))} | #{rep.index} seed {rep.seed}"
                     f"{video} | {_cell(status)} | {_cell(c.bank_entry)} | {_reproduction_text(c)} | "
                     f"{_num(c.e2e_sc, 3)} |")
    return lines


def _summary_lines(report: MineReport) -> List[str]:
    """The report's title, headline, breadth and failure rate, the table of counts, failures by type and the
    conversions' times."""
    counts = report.counts
    lines = [f"## dv2s mine: {counts.avoidable_clusters} avoidable failure cluster(s)", "", headline(report), "",
             breadth(counts) + ".", "", rate_text(report.failure_rate), ""]
    lines += ["| failures | avoidable | unavoidable | unknown | clusters | avoidable clusters | converted | kept | "
              "merged | rejected | errors |", "|" + "---:|" * 11,
              f"| {counts.failures} | {counts.avoidable} | {counts.unavoidable} | "
              f"{counts.avoidability_unknown} | {counts.clusters} | {counts.avoidable_clusters} | "
              f"{counts.converted} | {counts.kept} | {counts.merged} | {counts.rejected} | "
              f"{counts.errors} |", ""]
    if counts.failures_by_type:
        lines += ["Failures by type: " + by_type_text(counts.failures_by_type), ""]
    seconds = counts.conversion_seconds
    if seconds["n"]:
        stages = counts.conversion_stage_seconds or {}
        lines += [f"Conversion time: median {seconds['median']:.2f} s, max {seconds['max']:.2f} s over "
                  f"{seconds['n']} conversion(s)" + ("; median per stage: " + ", ".join(
                      f"{stage} {value:.2f} s" for stage, value in stages.items()) if stages else "") + ".", ""]
    return lines


def _sampler_lines(report: MineReport) -> List[str]:
    """The per-sampler section: failures and clusters per 100 episodes, and the first failure."""
    lines = ["### Per sampler", "",
             "Failures per 100 episodes with Wilson 95% intervals (an adaptive sampler's episodes are not "
             "independent, so the interval is a guide).", "",
             "| sampler | episodes | failures | failures per 100 | avoidable per 100 | clusters | clusters per 100 | "
             "avoidable clusters | first failure at episode |",
             "|---|---:|---:|---|---|---:|---:|---:|---:|"]
    for name, s in report.samplers.items():
        lines.append(f"| {_cell(name)} | {s.episodes} | {s.failures} | {_per_100_text(s.failures_per_100)} | "
                     f"{_per_100_text(s.avoidable_failures_per_100)} | {s.clusters} | "
                     f"{_num(s.clusters_per_100)} | {s.avoidable_clusters} | "
                     f"{_cell(s.episodes_to_first_failure)} |")
    return lines


def _scenario_lines(report: MineReport) -> List[str]:
    """The per-scenario section: sampled and estimated failure rates, failure types, behaviours and conversions."""
    lines = ["", "### Per scenario", "",
             "Sampled failure rate: failures per episode as the sampler drew them; estimated: under the scenario's "
             "own parameter distribution (importance-weighted; effective sample size in brackets).", "",
             "| scenario | episodes | failures | sampled failure rate [95% CI] | estimated rate [95% CI] (ESS) | "
             "failure types | avoidable | unavoidable | behaviours | converted | kept |",
             "|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|"]
    for name, s in report.scenarios.items():
        estimate = s.estimated_rate
        estimated = f"{_pct(estimate)} ({_num((estimate or {}).get('ess'))})" if estimate else "-"
        types = "-" if s.failure_types is None else s.failure_types
        lines.append(f"| `{_cell(name)}` | {s.episodes} | {s.failures} | {_pct(s.failure_rate)} | "
                     f"{estimated} | {types} | "
                     f"{s.avoidable} | {s.unavoidable} | {s.clusters} | {s.converted} | {s.kept} |")
    return lines


def _cluster_lines(report: MineReport) -> List[str]:
    """The failure clusters' section: a table of the clusters that count against the policy."""
    lines = ["", f"### Failure clusters ({len(report.clusters)})", ""]
    lines += _cluster_rows(report.clusters) if report.clusters else ["None."]
    return lines


def _converted_lines(report: MineReport) -> List[str]:
    """The converted failures' section (kept first, then merged: where each went, its reproduction, video and
    script), and the count of the conversions' parameter check."""
    counts = report.counts
    lines: List[str] = []
    converted = [c for c in report.clusters + report.unavoidable_clusters if c.conversion is not None]
    described = sorted((c for c in converted if c.status in (ConversionStatus.KEPT, ConversionStatus.MERGED)),
                       key=lambda c: c.status != ConversionStatus.KEPT)
    if described:
        lines += ["", "### Converted failures", ""]
        for c in described:
            where = f"bank entry `{c.bank_entry}`" if c.bank_entry else (
                f"merged into `{c.merged_into}`" if c.merged_into else c.status)
            lines.append(f"- `{_cell(c.id)}` ({where}; reproduction {_reproduction_text(c)}; "
                         f"E2E-SC {_num(c.e2e_sc, 3)}): video {c.video or '-'}, script "
                         f"{c.script or '-'}")
            if c.description:
                lines.append(f"  > {_cell(c.description)}")
    lines += _replay_entry_lines(converted)
    if counts.parameters_compared or counts.parameters_not_compared:
        lines += ["", parameter_check_text(counts) + " (each conversion record lists the parameters not compared, "
                      "with why, under `parameters.not_comparable`)."]
    return lines


def _replay_entry_lines(converted: Sequence[ClusterEntry]) -> List[str]:
    """The exact replay entries the conversions kept in the bank, each with the parameters its replay could not
    narrow around the failing values (drawn as the parent draws them) and why."""
    kept = [c for c in converted if c.replay_entry]
    if not kept:
        return []
    lines = ["", "### Exact replay entries", "",
             "Each replays its failing scene with the parent's parameters narrowed around the failing values; the "
             "parameters listed could not be narrowed and are drawn as in the parent.", ""]
    for c in kept:
        missed = c.replay_not_narrowed or {}
        lines.append(f"- `{_cell(c.replay_entry)}` (cluster `{_cell(c.id)}`): "
                     + ("every parameter narrowed" if not missed else "not narrowed: " + "; ".join(
                         f"{_cell(name)} ({_cell(why)})" for name, why in sorted(missed.items()))))
    return lines


def _rejected_lines(report: MineReport) -> List[str]:
    """The rejected conversions' section: counts by stage and a table of each with its reason (none: nothing)."""
    if not report.rejected:
        return []
    lines = ["", f"### Rejected conversions ({len(report.rejected)})", "",
             "By stage: " + ", ".join(f"{s} {n}" for s, n in report.counts.rejected_by_stage.items()), "",
             "| cluster | episode | stage | reason |", "|---|---:|---|---|"]
    lines += [f"| `{_cell(r.cluster)}` | {_cell(r.index)} | {_cell(r.stage)} | {_cell(r.reason)} |"
              for r in report.rejected]
    return lines


def _unavoidable_lines(report: MineReport) -> List[str]:
    """The unavoidable failures' section: their clusters' table and a line per failure (the first 50)."""
    lines = ["", f"### Unavoidable failures ({len(report.unavoidable)})", "",
             "The reference driver failed in the same scene too; these do not count against the policy."]
    if report.unavoidable_clusters:
        lines += [""] + _cluster_rows(report.unavoidable_clusters)
    if report.unavoidable:
        lines += [""] + [f"- #{f.index} `{_cell(f.scenario)}` seed {f.seed}: {f.type} "
                         f"(reference: {_cell(f.reference.failure_type if f.reference is not None else None)}); "
                         f"cluster `{_cell(f.cluster)}`" for f in report.unavoidable[:50]]
        if len(report.unavoidable) > 50:
            lines.append(f"- ... and {len(report.unavoidable) - 50} more (see report.json)")
    return lines


def _replay_lines(report: MineReport) -> List[str]:
    """The command that replays a failure exactly from its trace (none without a failure that has one)."""
    if not report.failures:
        return []
    example = next((f for f in report.failures if f.trace), None)
    if example is None:
        return []
    return ["", f"Replay a failure exactly from its trace: `dv2s replay {report.run_dir or '.'}/"
                f"{example.trace} --video failure.webm`."]


def _trouble_lines(report: MineReport) -> List[str]:
    """What went wrong while mining: the episodes that errored (the first 20), those a new worker finished, and
    the truncated lines of a killed run left out."""
    lines: List[str] = []
    if report.errors:
        lines += ["", f"### Errors ({len(report.errors)})", ""]
        lines += [f"- #{e.index} `{_cell(e.scenario)}` seed {e.seed}: {_cell(e.error.splitlines()[0] if e.error else '')}"
                  for e in report.errors[:20]]
        if len(report.errors) > 20:
            lines.append(f"- ... and {len(report.errors) - 20} more (see report.json)")
    if report.worker_restarts:
        lines += ["", f"### Worker restarts ({len(report.worker_restarts)})", "",
                  "Episodes whose worker crashed or hung (`--timeout`) and were finished by a new worker:", ""]
        lines += [f"- #{r.index} `{_cell(r.scenario)}` seed {r.seed}: {_cell('; then '.join(r.problems))}"
                  for r in report.worker_restarts[:20]]
    if report.skipped_lines:
        lines += ["", "Left out (truncated last lines of a killed run): "
                  + ", ".join(f"{name} {n}" for name, n in report.skipped_lines.items())]
    return lines


def markdown(report: MineReport) -> str:
    """The report as Markdown: summary, per sampler, per scenario, clusters, conversions, unavoidable, errors."""
    report = mine_report(report, "markdown")
    lines = (_summary_lines(report) + _sampler_lines(report) + _scenario_lines(report) + _cluster_lines(report)
             + _converted_lines(report) + _rejected_lines(report) + _unavoidable_lines(report)
             + _replay_lines(report) + _trouble_lines(report))
    lines.append("")
    return "\n".join(lines)


def write_reports(run_dir: PathLike, report: Optional[MineReport] = None, *,
                  embed_videos: bool = True) -> Dict[str, Path]:
    """Write ``report.json`` (atomic), ``report.md`` and ``report.html`` into the run folder.

    Args:
        run_dir: the run folder (``--out`` of ``dv2s mine``).
        report: a report already built from it (a :class:`MineReport`; default: :func:`build_report`).
        embed_videos: embed the failure videos in the HTML page (else it links them relatively).

    Returns:
        ``{"json": path, "markdown": path, "html": path}``.
    """
    run_dir = Path(run_dir)
    report = mine_report(report, "write_reports") if report is not None else build_report(run_dir)
    return {"json": atomic_write_json(run_dir / "report.json", report.to_dict()),
            "markdown": atomic_write_text(run_dir / "report.md", markdown(report)),
            "html": write_html(report, run_dir / "report.html", base=run_dir, embed_videos=embed_videos)}
