"""The regression report: built from paired episode results, written as JSON, JUnit XML and Markdown.

:func:`build_report` gives a :class:`~dv2s_gym.regress.records.RegressReport` (its parts typed records of
:mod:`dv2s_gym.regress.records`, read by attribute); its ``to_json()`` is the JSON object below, key for key and in
this order, and :func:`load_report` reads a ``report.json`` back into one.

JSON schema ``dv2s-regress``, version 4 (:data:`SCHEMA_VERSION`; a change to any key below
bumps it, and ``--baseline-report`` refuses a report of another version: version 3 did not record the
``"files read by detectors"``, so a version 3 baseline cannot say which files decided its failure kinds)::

    {
      "schema": "dv2s-regress", "schema_version": 4,
      "created": ISO-8601 time (UTC), "dv2s_version": "0.1.0",
      "code_identity": {"dv2s sources (SHA-256)", "plug-in modules": {module: SHA-256 of its source},
                        "detectors": {kind: {"failure type": module, "detector": module,
                                             "sources (SHA-256)": {module: SHA-256}}},
                        "replaced built-ins": [phrases],
                        "files read by detectors": {kind: {"user file limits.json read by myfail (SHA-256)":
                                                             SHA-256, ...}}}
                                                   the code that judged the episodes,
      "bank": {"path": bank folder, "version": SHA-256 over the scenarios used (name + script),
               "scenarios": [names], "hashes": {name: SHA-256 of its script}},
      "settings": {"episodes", "seed", "margin", "alpha", "sequential", "env_config", "backend",
                   "workers", "timeout"},
      "candidate": {"spec": policy spec, "card": model card dict or null},
      "baseline": {"spec", "card"} | {"report": path, "spec", "card"} | null,
      "episodes": [{"id": "scenario/seed", "scenario", "seed",
                    "candidate": Episode, "baseline": Episode | null}],
      "scenarios": {name: {"candidate": Summary, "baseline": Summary | null,
                           "comparison": Comparison | null}},
      "overall": {"candidate": Summary, "baseline": Summary | null, "comparison": Comparison | null},
      "verdict": "PASS" | "FAIL" | "INCONCLUSIVE" | "ERROR" | null (no baseline, no error),
      "error_reason": one line (measures only, with errors; absent otherwise),
      "regressed": [scenario names whose verdict is FAIL],
      "newly_failing": [episode ids where the candidate failed and the baseline did not],
      "errors": [{"id", "role", "error"}],
      "stopped_early": bool,
      "sequential": {"looks", "episodes", "max_episodes", "verdict"} | null,
      "power": {"per_scenario": {name: Power}, "pooled": Power, "power", "mde", "assumption"} | null,
      "aggregates": {"return_iqm": {"candidate", "baseline"}, "probability_of_improvement",
                     "resamples", "confidence"} | null      context, not the verdict,
      "hostname": machine of the run, "duration": its wall time [s],
      "timing": {scenario: wall time of its episodes run in this invocation [s]}
    }

``Power`` (:func:`dv2s_gym.regress.power.run_power`): ``{"n", "baseline_rate", "level", "at_margin",
"at_mde", "detectable"}``: the probability the run had to FAIL an increase of the margin and of the
planned ``mde``, and the smallest increase it detected with the planned power. ``settings`` also
holds ``mde``, ``power`` and, for a run sized by them, ``plan``.

``Episode`` is the JSON object of a :class:`~scenario_bank.records.RegressEpisode`, as ``results.jsonl``
holds it: :meth:`policies.evaluation.EpisodeResult.to_json` (scenario, seed, scene_seed,
sampled ``params``, collided, collisions, off_road, success, failed, min_ttc (null when no
vehicle was ever on a collision course), mean_speed, distance, episode_return, steps,
trajectory_hash, error, extra) plus ``role``, ``id``, ``trace`` (path of the saved trace,
relative to the report's folder, for failed episodes; else null), ``stalled``, ``stall_time`` and
``failure_kinds``. An episode that produced no
result (an exception, or a worker that crashed or hung twice) is
``{"id", "role", "scenario", "seed", "error", "trace": null}``.

``Summary`` (one policy, one scenario or all)::

    {"episodes": n (without errors), "errors": count,
     "collision_rate" | "off_road_rate" | "stall_rate" | "failure_rate" | "success_rate":
         {"value", "low", "high", "count"}          Wilson 95 % interval,
     "min_ttc" | "mean_speed" | "return": {"value", "low", "high", "n"}   bootstrap 95 % interval}

A failure is any of the run's failure kinds (``settings["failure"]``: collision, off-road and
stall by default; :mod:`dv2s_gym.regress.failures`); each kind has its own rate, whether it counts
as a failure or not. ``min_ttc`` is the mean over episodes of each
episode's minimum time-to-collision [s], over the ``n`` episodes where it was finite. The
means' intervals resample episodes within a scenario and whole scenarios for the overall
figure (``cluster_bootstrap_mean``), since episodes of one scenario are not independent.

``Comparison`` (candidate against baseline on the same scenario x seed pairs; pairs with an
error on either side are left out)::

    {"n": pairs, "table": {"both_fail", "candidate_only", "baseline_only", "neither"},
     "candidate_rate", "baseline_rate",
     "difference": {"value", "low", "high"}     failure-rate difference, Newcombe interval,
     "p_value": one-sided exact McNemar, "p_adjusted": p-value scaled by the family of tests (FAIL iff <= alpha),
     "verdict": "PASS" | "FAIL" | "INCONCLUSIVE" | "ERROR", "reason": one line}

Verdicts follow :mod:`dv2s_gym.regress.stats` (non-inferiority within ``margin``). The
overall verdict is FAIL when any scenario or the pooled table FAILs, PASS when the pooled
table PASSes and no scenario FAILs. An episode that ended in an error makes the verdict ERROR
(its scenario's too; a measures-only run's verdict becomes ERROR as well, with ``error_reason``),
whatever the other episodes show, and such a report cannot serve as a baseline.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from dv2s_gym.regress import stats
from dv2s_gym.regress.aggregates import return_aggregates
from dv2s_gym.regress.errors import RegressError, ReportMismatchError
from dv2s_gym.regress.failures import failure_kinds, result_value
from policies.run_identity import BUILT_IN, DETECTOR_READS, changed_files, installed_version, report_code_identity
from policies.stats import Rate
from dv2s_gym.regress.power import DEFAULT_MDE, DEFAULT_POWER, run_power
from dv2s_gym.regress.records import (BankInfo, EpisodeError, PairedComparison, PairedEpisode, PolicyInfo,
                                      RegressReport, ReportSettings, RunPower, ScenarioResult, SequentialOutcome,
                                      Summary, as_result)
from dv2s_gym.regress.store import describe_differences
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.bank import Bank, content_hash
from scenario_bank.named_registry import replaced_text
from scenario_bank.records import RecordError, RegressEpisode, recorded

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "EXIT_CODES",
    "exit_code",
    "summarize",
    "summarize_groups",
    "comparison_json",
    "bank_info",
    "build_report",
    "load_report",
    "baseline_defaults",
    "check_baseline_report",
    "check_baseline_code",
    "write_json",
    "write_markdown",
    "format_summary", "failures_text", "headline", "paired_tables", "power_lines", "scenarios_by_severity", "warnings"]

SCHEMA = "dv2s-regress"
SCHEMA_VERSION = 4
"""The format of ``report.json`` (bumped when its fields change; a report of another version is refused)."""
CONFIDENCE = 0.95


def rates() -> Tuple[Tuple[str, str], ...]:
    """A summary's rates and the result field each counts: one per failure kind of the live failure table
    (:func:`dv2s_gym.regress.failures.failure_kinds`), then any failure and success."""
    return tuple((f"{kind}_rate", field) for kind, field in failure_kinds().items()) + (
        ("failure_rate", "failed"), ("success_rate", "success"))


MEANS = (("min_ttc", "min_ttc"), ("mean_speed", "mean_speed"), ("return", "episode_return"))

EXIT_CODES = {"PASS": 0, "FAIL": 1, "INCONCLUSIVE": 3, "ERROR": 4, None: 0}
"""Exit status of ``dv2s regress`` per verdict (2 stays "bad input"); no baseline and no error: 0."""

VERDICTS = ("PASS", "FAIL", "INCONCLUSIVE", "ERROR")
"""Every verdict a report can carry (``None``: measures only, every episode ran)."""


def exit_code(verdict: Optional[str]) -> int:
    """The exit status for a report's verdict: 0 PASS (or measures only), 1 FAIL, 3 INCONCLUSIVE, 4 ERROR."""
    return EXIT_CODES[verdict]


def _error_reason(errors: Sequence[EpisodeError]) -> str:
    first = errors[0]
    message = first.first_line or "no result"
    return (f"{len(errors)} episode{'s' if len(errors) != 1 else ''} ended in an error, so the run cannot be judged "
            f"(first: {first.id} ({first.role}): {message}); fix the error and rerun the same command to "
            "run them again")


def _verdict(value: Any) -> str:
    """``Verdict.FAIL`` or ``"fail"`` -> ``"FAIL"``."""
    return str(getattr(value, "name", value)).upper()


# ------------------------------------------------------------------------------ summaries
def _ok(results: Sequence[RegressEpisode]) -> List[RegressEpisode]:
    return [r for r in results if r is not None and not r.error]


def _rate(values: Sequence[bool]) -> Dict[str, Any]:
    return Rate.of(sum(bool(v) for v in values), len(values), CONFIDENCE).report_json()


def _mean(groups: Sequence[Sequence[float]]) -> Dict[str, Any]:
    groups = [list(g) for g in groups if len(g)]
    n = sum(len(g) for g in groups)
    if n == 0:
        return {"value": None, "low": None, "high": None, "n": 0}
    value, low, high = stats.cluster_bootstrap_mean(groups, CONFIDENCE, n_resamples=2000, seed=0)
    return {"value": value, "low": low, "high": high, "n": n}


def _finite(value: Any) -> Optional[float]:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def summarize_groups(groups: Mapping[str, Sequence[RegressEpisode]], *, episode_groups: bool = False) -> Summary:
    """Summary over several scenarios: rates over all episodes, means resampling whole scenarios.

    With ``episode_groups`` every episode is its own group (the within-scenario interval). A result is a
    :class:`~scenario_bank.records.RegressEpisode` (a JSON object is read with :func:`~dv2s_gym.regress.records.as_result`
    where it is read).
    """
    groups = {name: [r for r in results if r is not None] for name, results in groups.items()}
    every = [r for results in groups.values() for r in results]
    ok = _ok(every)
    means: Dict[str, Any] = {}
    for key, field in MEANS:
        per_group = [[v for v in (_finite(result_value(r, field)) for r in _ok(results)) if v is not None]
                     for results in groups.values()]
        if episode_groups:
            per_group = [[v] for values in per_group for v in values]
        means[key] = _mean(per_group)
    return Summary(episodes=len(ok), errors=len(every) - len(ok),
                   rates={key: _rate([bool(result_value(r, field)) for r in ok]) for key, field in rates()},
                   min_ttc=means["min_ttc"], mean_speed=means["mean_speed"], episode_return=means["return"])


def summarize(results: Sequence[RegressEpisode]) -> Summary:
    """Summary of one policy on one scenario (episodes resampled for the means' intervals)."""
    return summarize_groups({"": results}, episode_groups=True)


# ----------------------------------------------------------------------------- comparisons
def comparison_json(comparison: "stats.Comparison", *, verdict: Optional[str] = None,
                    reason: Optional[str] = None) -> PairedComparison:
    """A :class:`~dv2s_gym.regress.stats.Comparison` as the report's ``Comparison`` record."""
    table = comparison.table
    low, high = comparison.interval
    return PairedComparison(
        n=table.n,
        table={"both_fail": table.both_fail, "candidate_only": table.candidate_only,
               "baseline_only": table.baseline_only, "neither": table.neither},
        candidate_rate=table.candidate_rate,
        baseline_rate=table.baseline_rate,
        difference={"value": comparison.difference, "low": low, "high": high},
        p_value=comparison.p_value,
        p_adjusted=getattr(comparison, "p_adjusted", getattr(comparison, "adjusted_p", comparison.p_value)),
        verdict=verdict or _verdict(comparison.verdict),
        reason=reason or comparison.reason,
    )


def _complete(pair: PairedEpisode) -> bool:
    """Both policies ran the pair and neither ended in an error."""
    return pair.baseline is not None and not pair.errored("candidate") and not pair.errored("baseline")


def _paired_table(pairs: Sequence[PairedEpisode]) -> "stats.PairedTable":
    complete = [p for p in pairs if _complete(p)]
    return stats.PairedTable.from_outcomes([bool(p.candidate.failed) for p in complete],
                                           [bool(p.baseline.failed) for p in complete])


def paired_tables(episodes: Sequence[PairedEpisode], scenarios: Sequence[str]) -> Dict[str, "stats.PairedTable"]:
    """The paired table of each scenario (pairs with an error on either side left out)."""
    by_scenario: Dict[str, List[PairedEpisode]] = {name: [] for name in scenarios}
    for episode in episodes:
        by_scenario.setdefault(episode.scenario, []).append(episode)
    return {name: _paired_table(pairs) for name, pairs in by_scenario.items()}


def _errors_note(count: int) -> str:
    return f"{count} episode{'s' if count != 1 else ''} ended in an error, so it cannot be judged"


# ---------------------------------------------------------------------------------- report
def bank_info(scenarios: Sequence[str], bank_dir: Optional[Union[str, os.PathLike]] = None) -> BankInfo:
    """The bank's path, the scenarios and their script hashes; the version is a SHA-256 over the scenarios' names and
    scripts."""
    bank = Bank(bank_dir)
    hashes = {name: content_hash(bank.get(name).script) for name in scenarios}
    payload = "\n".join(f"{name}:{hashes[name]}" for name in sorted(hashes))
    return BankInfo(path=str(Path(bank.root).resolve()), version=hashlib.sha256(payload.encode()).hexdigest(),
                    scenarios=tuple(scenarios), hashes=hashes)


def build_report(*, bank: BankInfo, settings: ReportSettings, candidate: PolicyInfo, baseline: Optional[PolicyInfo],
                 episodes: Sequence[PairedEpisode], stopped_early: bool = False,
                 sequential: Optional[SequentialOutcome] = None,
                 code_identity: Optional[Mapping[str, Any]] = None) -> RegressReport:
    """The report (schema in the module docstring) from the paired episodes.

    Args:
        bank: the bank's :class:`~dv2s_gym.regress.records.BankInfo`.
        settings: the run's :class:`~dv2s_gym.regress.records.ReportSettings` (``margin`` and ``alpha`` decide the
            verdicts).
        candidate / baseline: :class:`~dv2s_gym.regress.records.PolicyInfo`; ``baseline`` None for a run without
            one.
        episodes: :class:`~dv2s_gym.regress.records.PairedEpisode`, each result a
            :class:`~scenario_bank.records.RegressEpisode`.
        stopped_early / sequential: the sequential test's outcome (a
            :class:`~dv2s_gym.regress.records.SequentialOutcome`; its ``verdict``, when set, is the overall verdict of
            a sequential run; a scenario FAIL still FAILs).
        code_identity: the code that judged the episodes
            (:func:`policies.run_identity.report_code_identity`); default: this process's, for the run's failure
            kinds.
    """
    scenarios = list(bank.scenarios or ())
    paired = sorted(episodes, key=lambda e: (
        scenarios.index(e.scenario) if e.scenario in scenarios else len(scenarios), e.scenario, int(e.seed)))
    has_baseline = baseline is not None
    by_scenario: Dict[str, List[PairedEpisode]] = {name: [] for name in scenarios}
    for episode in paired:
        by_scenario.setdefault(episode.scenario, []).append(episode)

    def results(name: str, role: str) -> List[RegressEpisode]:
        return [e.result(role) for e in by_scenario[name] if e.result(role) is not None]

    errors = [EpisodeError(id=e.id, role=role, error=e.result(role).error) for e in paired
              for role in ("candidate", "baseline") if e.errored(role)]
    compared = _compare(paired, by_scenario, errors, settings, sequential) if has_baseline else _Compared()
    report_scenarios = {name: ScenarioResult(
        candidate=summarize(results(name, "candidate")),
        baseline=summarize(results(name, "baseline")) if has_baseline else None,
        comparison=compared.per_scenario.get(name)) for name in by_scenario}
    overall = ScenarioResult(
        candidate=summarize_groups({n: results(n, "candidate") for n in by_scenario}),
        baseline=summarize_groups({n: results(n, "baseline") for n in by_scenario}) if has_baseline else None,
        comparison=compared.overall)
    verdict, error_reason = compared.verdict, None
    if errors and verdict is None:  # measures only: an error is still never green
        verdict, error_reason = "ERROR", _error_reason(errors)
    return RegressReport(
        schema=SCHEMA, schema_version=SCHEMA_VERSION,
        created=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        dv2s_version=installed_version(),
        code_identity=dict(code_identity) if code_identity is not None else report_code_identity(
            settings.failure or ()), bank=bank, settings=settings, candidate=candidate,
        baseline=baseline if has_baseline else None, episodes=tuple(paired),
        scenarios=report_scenarios, overall=overall, verdict=verdict, regressed=tuple(compared.regressed),
        newly_failing=tuple(compared.newly_failing), errors=tuple(errors), stopped_early=bool(stopped_early),
        sequential=sequential, power=compared.power, aggregates=compared.aggregates, error_reason=error_reason)


@dataclasses.dataclass
class _Compared:
    """The candidate against the baseline: each scenario's comparison and the pooled verdict (empty without a
    baseline)."""

    per_scenario: Dict[str, PairedComparison] = dataclasses.field(default_factory=dict)
    overall: Optional[PairedComparison] = None
    verdict: Optional[str] = None
    regressed: List[str] = dataclasses.field(default_factory=list)
    newly_failing: List[str] = dataclasses.field(default_factory=list)
    power: Optional[RunPower] = None
    aggregates: Optional[Dict[str, Any]] = None


def _compare(episodes: List[PairedEpisode], by_scenario: Dict[str, List[PairedEpisode]],
             errors: List[EpisodeError], settings: ReportSettings,
             sequential: Optional[SequentialOutcome]) -> _Compared:
    """The paired comparisons of :func:`build_report` (a scenario with an errored episode is an ERROR)."""
    margin, alpha = float(settings.margin), float(settings.alpha)
    errors_in = {name: sum(1 for e in by_scenario[name] for role in ("candidate", "baseline") if e.errored(role))
                 for name in by_scenario}
    comparisons: Dict[str, PairedComparison] = {}
    tables = paired_tables(episodes, list(by_scenario))
    tested = sequential is not None and sequential.verdict is not None  # the pooled member was tested sequentially
    pooled_rejected = sequential.verdict == "FAIL" if tested else None
    per_scenario, overall = stats.compare_scenarios(tables, margin, alpha, pooled_rejected=pooled_rejected)
    for name, comparison in per_scenario.items():
        scenario_verdict, reason = _verdict(comparison.verdict), comparison.reason
        if errors_in[name]:
            scenario_verdict, reason = "ERROR", f"{_errors_note(errors_in[name])}; {reason}"
        comparisons[name] = comparison_json(comparison, verdict=scenario_verdict, reason=reason)
    verdict, reason = _verdict(overall.verdict), overall.reason
    if tested:
        reason = (f"sequential test of the pooled table ({sequential.looks} looks, "
                  f"{sequential.episodes} of {sequential.max_episodes} paired episodes): "
                  f"{sequential.verdict}; {reason}")
    if errors:
        verdict, reason = "ERROR", f"{_error_reason(errors)}; without them: {verdict}, {reason}"
    newly_failing = [e.id for e in episodes if _complete(e) and e.candidate.failed and not e.baseline.failed]
    return _Compared(per_scenario=comparisons, overall=comparison_json(overall, verdict=verdict, reason=reason),
                     verdict=verdict, regressed=[name for name, c in comparisons.items() if c.verdict == "FAIL"],
                     newly_failing=newly_failing, power=_power(tables, margin, alpha, settings),
                     aggregates=return_aggregates(episodes))


def _power(tables: Mapping[str, "stats.PairedTable"], margin: float, alpha: float,
           settings: ReportSettings) -> RunPower:
    """The power the run had (:func:`dv2s_gym.regress.power.run_power`), from its baseline's observed failure rates."""
    rates = {name: (table.baseline_rate if table.n else None) for name, table in tables.items()}
    return run_power({name: table.n for name, table in tables.items()}, rates, margin=margin, alpha=alpha,
                     mde=float(settings.mde or DEFAULT_MDE), power=float(settings.power or DEFAULT_POWER))



# ---------------------------------------------------------------------- baseline reports
def baseline_defaults(path: Union[str, os.PathLike], seed: Optional[int], env_config: Optional[Dict[str, Any]],
                      failure: Union[None, str, Sequence[str]] = None
                      ) -> Tuple[Optional[int], Optional[Dict[str, Any]], Union[None, str, Sequence[str]]]:
    """The seed, env config and failure kinds of a run against the baseline report at ``path``: those given, else
    the report's (by default a run repeats the episodes the baseline ran and judges them as it did).

    Raises:
        RegressError: the report's failure kinds, taken because ``failure`` is ``None``, are not all known here
            (their plug-ins are not loaded), naming the kinds, the plug-in modules the report records for them and
            the fix.
    """
    if seed is not None and env_config is not None and failure is not None:
        return seed, env_config, failure
    report = load_report(path)
    old = report.settings
    if failure is None and old.failure:
        _check_report_kinds_known(report, path, list(old.failure))
    return (old.seed if seed is None else seed,
            old.env_config if env_config is None else env_config,
            (list(old.failure) if old.failure else None) if failure is None else failure)


def _check_report_kinds_known(report: RegressReport, path: Union[str, os.PathLike], kinds: Sequence[str]) -> None:
    """Refuse the failure ``kinds`` a baseline report was judged on when some are unknown here, naming the plug-in
    modules the report records for them (``code_identity["detectors"]``) and the fix."""
    known = failure_kinds()
    unknown = [kind for kind in kinds if kind not in known]
    if not unknown:
        return
    detectors = dict((report.code_identity or {}).get("detectors") or {})
    modules: Dict[str, List[str]] = {}
    for kind in unknown:
        entry = detectors.get(kind)
        entry = entry if isinstance(entry, Mapping) else {}
        modules[kind] = sorted({str(entry.get(role)) for role in ("failure type", "detector")
                                if entry.get(role) and entry.get(role) != BUILT_IN})
    named = "; ".join(f"{kind}: plug-in module {', '.join(found)}" if found else f"{kind}: no plug-in module recorded"
                      for kind, found in modules.items())
    needed = sorted({module for found in modules.values() for module in found})
    load = f"load them with DV2S_PLUGINS={','.join(needed)}, or " if needed else ""
    raise RegressError(
        f"baseline report {path} was judged on failure kind{'s' if len(unknown) > 1 else ''} "
        f"{', '.join(unknown)}, unknown here ({named}); {load}pass --failure with kinds this run knows "
        f"({', '.join(known)})")


def load_report(path: Union[str, os.PathLike]) -> RegressReport:
    """Read a report written by ``dv2s regress``, check its schema and version, and give its record."""
    path = Path(path)
    if not path.is_file():
        raise RegressError(f"baseline report {path} does not exist; give the report.json of an earlier "
                           "`dv2s regress` run")
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise RegressError(f"baseline report {path} is not readable JSON ({error}); give the report.json "
                           "of an earlier `dv2s regress` run") from None
    if not isinstance(report, dict) or report.get("schema") != SCHEMA:
        found = report.get("schema") if isinstance(report, dict) else type(report).__name__
        raise ReportMismatchError(f"{path} is not a dv2s regress report (schema {found!r}, expected "
                                  f"{SCHEMA!r}); give the report.json of an earlier `dv2s regress` run")
    version = report.get("schema_version")
    if version != SCHEMA_VERSION:
        raise ReportMismatchError(
            f"baseline report {path} has schema version {version}, this dv2s-gym reads version "
            f"{SCHEMA_VERSION}; rerun the baseline with this version (dv2s regress --policy BASELINE) "
            "and compare against that report")
    try:
        return RegressReport.from_json(report)
    except RecordError as error:
        raise ReportMismatchError(f"report {path} is damaged: {error}; give the report.json of an earlier "
                                  "`dv2s regress` run") from None


def check_baseline_report(report: RegressReport, *, path: Union[str, os.PathLike], bank: BankInfo,
                          env_config: Mapping[str, Any]) -> None:
    """Refuse a baseline report with errors, or whose bank scenarios or env config differ from this run's,
    saying what differs."""
    errors = report.errors or ()
    if errors:
        first = errors[0]
        raise ReportMismatchError(
            f"baseline report {path} cannot be a baseline: {len(errors)} of its episodes ended in an error "
            f"(first: {first.id} ({first.role}): {first.first_line[:160]}); "
            "rerun that run's command until it has no errors, and compare against that report")
    theirs = report.bank if report.bank is not None else BankInfo()
    their_hashes = theirs.hashes or {}
    missing = [n for n in bank.scenarios if n not in their_hashes]
    if missing:
        raise ReportMismatchError(
            f"baseline report {path} has no episodes of {', '.join(missing[:5])}"
            f"{' and more' if len(missing) > 5 else ''} (it covers {', '.join(theirs.scenarios or []) or 'nothing'}); "
            "select scenarios it covers with --scenarios, or rerun the baseline on these")
    changed = [n for n in bank.scenarios if their_hashes[n] != bank.hashes[n]]
    if changed:
        details = ", ".join(f"{n} (script {their_hashes[n][:12]} there, {bank.hashes[n][:12]} here)"
                            for n in changed[:3])
        raise ReportMismatchError(
            f"baseline report {path} was made with another bank version (bank version {str(theirs.version)[:12]}"
            f" there, {str(bank.version)[:12]} here): changed scenario{'s' if len(changed) > 1 else ''} "
            f"{details}{' and more' if len(changed) > 3 else ''}; rerun the baseline on this bank "
            "(--baseline POLICY instead of --baseline-report)")
    their_config = (report.settings.env_config if report.settings is not None else None) or {}
    if dict(their_config) != dict(env_config):
        raise ReportMismatchError(
            f"baseline report {path} used another env config ({describe_differences(dict(env_config), dict(their_config))});"
            " run with the same --config, or rerun the baseline")


def _judge(entry: Any) -> str:
    """Who decided a failure kind, from a report's ``code_identity["detectors"][kind]``."""
    if not isinstance(entry, Mapping):
        return "no recorded detector"
    sources = entry.get("sources (SHA-256)") or {}

    def named(module: Any) -> str:
        return str(module) + (f" (source {str(sources[module])[:12]})" if module in sources else "")
    text = f"detector {named(entry.get('detector'))}"
    if entry.get("failure type") != BUILT_IN:
        text += f", failure type {named(entry.get('failure type'))}"
    return text


_OTHER_CODE = ("dv2s sources (SHA-256)", "plug-in modules", "replaced built-ins")
"""The parts of a report's ``code_identity`` besides the judged kinds' detectors: a difference is flagged."""


def check_baseline_code(report: RegressReport, *, path: Union[str, os.PathLike], kinds: Sequence[str],
                        code_identity: Mapping[str, Any]) -> Optional[str]:
    """Refuse a baseline report whose detector for any failure kind of ``kinds`` differs from this run's
    (``code_identity``: :func:`policies.run_identity.report_code_identity`), naming the kind and both sides; give
    a warning naming the other parts of the code that differ (``None``: none does).

    Raises:
        ReportMismatchError: the kinds' episodes would be counted by two different detectors.
    """
    theirs = dict(report.code_identity or {})
    their_detectors, our_detectors = dict(theirs.get("detectors") or {}), dict(code_identity.get("detectors") or {})
    judged = list(report.settings.failure or ()) if report.settings is not None else []
    missing = [kind for kind in kinds if judged and kind not in judged]
    if missing:
        raise ReportMismatchError(
            f"baseline report {path} was judged on {', '.join(judged)} only, not on {', '.join(missing)}; pass "
            f"--failure {','.join(judged)} (or leave --failure out: a run against a baseline report judges what it "
            f"judged), or rerun the baseline with --failure {','.join(kinds)}")
    for kind in kinds:
        if their_detectors.get(kind) != our_detectors.get(kind):
            raise ReportMismatchError(
                f"baseline report {path} judged failure kind {kind!r} with another detector than this run "
                f"({_judge(their_detectors.get(kind))} there, {_judge(our_detectors.get(kind))} here), so the two "
                f"sides would count {kind} differently; rerun the baseline with the same plug-ins as this run "
                "(DV2S_PLUGINS), or run it here with --baseline POLICY instead of --baseline-report")
    _check_detector_files(theirs, path, kinds)
    other = [part.replace(" (SHA-256)", "") for part in _OTHER_CODE if theirs.get(part) != code_identity.get(part)]
    if not other:
        return None
    return (f"baseline report {path} was made with other code ({', '.join(other)} differ): differences may not "
            "be the candidate's; rerun the baseline with this code to be sure")


def _check_detector_files(theirs: Mapping[str, Any], path: Union[str, os.PathLike], kinds: Sequence[str]) -> None:
    """Refuse a baseline report whose judged kinds' plug-ins read files (their :data:`DETECTOR_READS`) that differ
    here now, naming each file and both SHA-256."""
    recorded = theirs.get(DETECTOR_READS) or {}
    for kind in kinds:
        changed = changed_files(dict(recorded.get(kind) or {}))
        if changed:
            shown = "; ".join(changed[:3]) + (f"; and {len(changed) - 3} more" if len(changed) > 3 else "")
            raise ReportMismatchError(
                f"baseline report {path} judged failure kind {kind!r} by a plug-in that read files which differ "
                f"here now ({shown}), so the two sides would count {kind} differently; restore the files as the "
                "baseline read them, or rerun the baseline with the files as they are now")


# ----------------------------------------------------------------------------------- text
def _pct(value: Optional[float]) -> str:
    return "-" if value is None else f"{100 * value:.1f}%"


def _interval(entry: Optional[Mapping[str, Any]], percent: bool = True, digits: int = 2) -> str:
    if not entry or entry.get("value") is None:
        return "-"
    if percent:
        return f"{_pct(entry['value'])} [{_pct(entry['low'])}, {_pct(entry['high'])}]"
    return f"{entry['value']:.{digits}f} [{entry['low']:.{digits}f}, {entry['high']:.{digits}f}]"


def _pp(entry: Mapping[str, Any]) -> str:
    return (f"{100 * entry['value']:+.1f} pp [{100 * entry['low']:+.1f}, {100 * entry['high']:+.1f}]")


def failures_text(summary: Optional[Summary]) -> str:
    """A policy's failures in a report's summary as ``count/episodes (percent)`` (``-`` without a summary, or with
    an empty one)."""
    if not recorded(summary):
        return "-"
    rate = summary.failure_rate
    return f"{rate['count']}/{summary.episodes} ({_pct(rate['value'])})"


def _against(baseline: Optional[PolicyInfo], base: Optional[Path], quote: str = "") -> str:
    """`` vs baseline `spec` (the candidate policy of REPORT)`` (empty without a baseline)."""
    if baseline is None:
        return ""
    of = (f" (the {baseline.role or 'candidate'} policy of {quote}{_relative(baseline.report, base)}{quote})"
          if baseline.report else "")
    return f" vs baseline `{baseline.spec}`{of}"


def headline(report: RegressReport, base: Optional[Path] = None) -> str:
    """The one line that says what a report compared: the policies, the failure classes, the scenarios and
    episodes, the margin and alpha, the bank version (a baseline report's path relative to ``base``)."""
    settings = report.settings
    failure = ", ".join(settings.failure)
    return (f"candidate `{report.candidate.spec}`{_against(report.baseline, base)}; failure: {failure}; "
            f"{len(report.scenarios)} scenario(s) x "
            f"{settings.episodes} episode(s) from seed {settings.seed}; margin {100 * settings.margin:g} pp, "
            f"alpha {settings.alpha:g}; bank version {str(report.bank.version)[:12]}")


SEVERITY = {"ERROR": 0, "FAIL": 1, "INCONCLUSIVE": 2, "PASS": 3}


def scenarios_by_severity(report: RegressReport) -> List[str]:
    """Scenario names, worst first: ERROR, FAIL, INCONCLUSIVE, PASS, each by the largest rise in failure
    rate (measures only: by the candidate's failure rate), then by name."""

    def key(name: str) -> tuple:
        entry = report.scenario(name)
        comparison = entry.comparison
        errors = ((entry.candidate.errors or 0) if recorded(entry.candidate) else 0) + (
            (entry.baseline.errors or 0) if recorded(entry.baseline) else 0)
        verdict = (comparison.verdict if recorded(comparison) else None) or ("ERROR" if errors else None)
        rise = ((comparison.difference if recorded(comparison) else None) or {}).get("value")
        if rise is None:
            rise = ((entry.candidate.failure_rate if recorded(entry.candidate) else None) or {}).get("value") or 0.0
        return SEVERITY.get(verdict, 4), -float(rise), name

    return sorted(report.scenarios, key=key)


def warnings(report: RegressReport) -> List[str]:
    """What a reader must know before trusting the verdict (a baseline from another dv2s version or other code, a
    built-in entry such as a detector that plug-ins replaced, ...)."""
    baseline = report.baseline
    found = [str(baseline.warning)] if baseline is not None and baseline.warning else []
    replaced = list((report.code_identity or {}).get("replaced built-ins") or [])
    return found + ([replaced_text(replaced)] if replaced else [])


def power_lines(report: RegressReport) -> List[str]:
    """What the run could detect: the power per scenario and pooled at the margin and at the planned effect."""
    power = report.power
    if power is None:
        return []
    per = list((power.per_scenario or {}).values())
    pooled = power.pooled
    margin = 100 * float(report.settings.margin)
    target = float(power.power)

    def low(key: str) -> Optional[float]:
        values = [getattr(v, key) for v in per if getattr(v, key) is not None]
        return min(values) if values else None

    def share(value: Optional[float]) -> str:
        return "-" if value is None else f"{value:.2f}"

    detectable = [v.detectable for v in per if v.detectable is not None]
    worst = f"+{100 * max(detectable):.1f} pp" if len(detectable) == len(per) and per else "none below 100 pp"
    mde = power.mde
    lines = [f"power per scenario (lowest of {len(per)}): {share(low('at_margin'))} at the +{margin:g} pp margin"
             + (f", {share(low('at_mde'))} at +{100 * mde:g} pp" if mde else "")
             + f"; {target:.0%} power at {worst}",
             f"power pooled ({pooled.n} pairs): {share(pooled.at_margin)} at the +{margin:g} pp margin; "
             f"{target:.0%} power at " + (f"+{100 * pooled.detectable:.1f} pp" if pooled.detectable is not None
                                          else "none below 100 pp"),
             f"power model: {power.assumption}"]
    plan = report.settings.plan
    if plan is not None and plan.note:
        lines.append(f"note: {plan.note}")
    return lines


def _rows(report: RegressReport, order: Sequence[str], overall: str) -> List[Tuple[str, ScenarioResult]]:
    """The scenarios' entries in ``order``, then the overall one named ``overall``."""
    return [(name, report.scenario(name)) for name in order] + [(overall, report.overall)]


def format_summary(report: RegressReport) -> str:
    """The plain-text table ``dv2s regress`` prints."""
    rows = [("scenario", "n", "candidate fails", "baseline fails", "difference [95% CI]", "p (adjusted)", "verdict")]
    for name, entry in _rows(report, scenarios_by_severity(report), "OVERALL"):
        comparison = entry.comparison
        rows.append((name, str(entry.candidate.episodes), failures_text(entry.candidate),
                     failures_text(entry.baseline),
                     _pp(comparison.difference) if recorded(comparison) else "-",
                     f"{comparison.p_adjusted:.3g}" if recorded(comparison) else "-",
                     comparison.verdict if recorded(comparison) else "-"))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [headline(report)]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    if report.error_reason:
        lines.append(f"verdict: ERROR ({report.error_reason})")
    elif report.verdict is not None:
        lines.append(f"verdict: {report.verdict} ({report.overall.comparison.reason})")
        if report.regressed:
            lines.append(f"regressed: {', '.join(report.regressed)}")
    else:
        lines.append("no baseline: measures only, no verdict")
    lines += power_lines(report)
    lines += [f"warning: {w}" for w in warnings(report)]
    if report.errors:
        lines.append(f"{len(report.errors)} error(s): " + "; ".join(
            f"{e.id} ({e.role}): {e.error}" for e in report.errors[:3]))
    if report.stopped_early:
        lines.append("stopped early: the sequential test settled the verdict")
    return "\n".join(lines)


MARKDOWN_LIMIT = 60000
"""Characters a Markdown report may have (a pull-request comment holds 65536); longer details are cut."""


def _relative(path: Any, base: Optional[Path]) -> str:
    """``path`` relative to ``base`` (the Markdown file's folder) when it can be, else as it is."""
    if not path or base is None:
        return str(path)
    try:
        return Path(os.path.relpath(Path(path).resolve(), base.resolve())).as_posix()
    except ValueError:  # another drive
        return str(path)


def _details(summary: str, lines: Sequence[str]) -> List[str]:
    return ["<details>", f"<summary>{summary}</summary>", "", *lines, "", "</details>", ""]


def _verdict_line(report: RegressReport) -> str:
    verdict = report.verdict
    if report.error_reason:
        return f"**ERROR**: {report.error_reason}"
    comparison = report.overall.comparison
    if comparison is None:
        return "No baseline: measures only, no verdict."
    if verdict == "FAIL" and report.regressed:
        parts = []
        for name in [n for n in scenarios_by_severity(report) if n in report.regressed]:
            entry = report.scenario(name)
            parts.append(f"`{name}` {_pp(entry.comparison.difference)} "
                         f"({failures_text(entry.baseline)} -> {failures_text(entry.candidate)})")
        pooled = " and in all scenarios pooled" if "all scenarios pooled" in comparison.reason else ""
        return f"**FAIL**: the candidate fails more often in {'; '.join(parts)}{pooled}."
    if verdict == "ERROR":
        return f"**ERROR**: {comparison.reason}"
    return f"**{verdict}**: {comparison.reason}"


def _markdown_facts(report: RegressReport) -> List[str]:
    """The Markdown report's list under the verdict: the run's size and settings, what newly fails, errors."""
    settings = report.settings
    facts = [f"{len(report.scenarios)} scenario(s) x {settings.episodes} episode(s) from seed {settings.seed}; "
             f"failure: {', '.join(settings.failure)}; margin "
             f"{100 * settings.margin:g} pp, alpha {settings.alpha:g}"]
    if report.newly_failing:
        facts.append(f"{len(report.newly_failing)} newly failing episode(s) (candidate fails, baseline does not)")
    if report.errors:
        facts.append(f"{len(report.errors)} episode(s) ended in an error")
    if report.stopped_early:
        facts.append("stopped early: the sequential test settled the verdict")
    facts += power_lines(report)[:2]
    facts += [f"warning: {w}" for w in warnings(report)]
    return [f"- {fact}" for fact in facts] + [""]


def _markdown_newly_failing(report: RegressReport, report_path: str) -> List[str]:
    if not report.newly_failing:
        return []
    shown = report.newly_failing[:20]
    items = [f"Reproduce one from this folder: `dv2s replay {report_path} --episode ID --video out.webm` "
             "(`report.html` shows each beside the baseline's run of the same scene).", ""]
    items += [f"- `{episode_id}`" for episode_id in shown]
    if len(report.newly_failing) > len(shown):
        items.append(f"- ... and {len(report.newly_failing) - len(shown)} more (see `{report_path}`)")
    return _details(f"Newly failing episodes ({len(report.newly_failing)})", items)


def _markdown_comparison(report: RegressReport, order: Sequence[str]) -> List[str]:
    """The folded table of the paired comparisons, worst first (none without a baseline)."""
    if report.overall.comparison is None:
        return []
    table = ["| scenario | pairs | candidate failures | baseline failures | difference [95% CI] | p (adjusted) | verdict |",
             "|---|---:|---:|---:|---|---:|---|"]
    for name, entry in _rows(report, order, "**overall**"):
        c = entry.comparison
        table.append(f"| {name if name.startswith('**') else f'`{name}`'} | {c.n} | "
                     f"{failures_text(entry.candidate)} | {failures_text(entry.baseline)} | {_pp(c.difference)} | "
                     f"{c.p_adjusted:.3g} | {c.verdict} |")
    return _details("Scenarios, worst first", table)


def _markdown_measures(report: RegressReport, order: Sequence[str]) -> List[str]:
    """The folded table of each policy's measures per scenario and overall."""
    measures = ["| scenario | policy | episodes | collision | off-road | stall | success | min TTC [s] | mean speed [m/s] | return |",
                "|---|---|---:|---|---|---|---|---|---|---|"]
    for name, entry in _rows(report, order, "**overall**"):
        for role in ("candidate", "baseline"):
            s = entry.summary(role)
            if not recorded(s):
                continue
            label = name if name.startswith("**") else f"`{name}`"
            measures.append(f"| {label} | {role} | {s.episodes} | {_interval(s.rate('collision'))} | "
                            f"{_interval(s.rate('off_road'))} | {_interval(s.rate('stall'))} | "
                            f"{_interval(s.success_rate)} | {_interval(s.min_ttc, False)} | "
                            f"{_interval(s.mean_speed, False, 1)} | {_interval(s.episode_return, False)} |")
    return _details("Measures per scenario (95% intervals)", measures)


def _markdown(report: RegressReport, report_path: str = "report.json", base: Optional[Path] = None) -> str:
    """The Markdown report for a pull-request comment: the verdict and what to look at first, the rest folded."""
    title = (f"## dv2s regress: {report.verdict or 'measures (no baseline)'} - candidate `{report.candidate.spec}`"
             f"{_against(report.baseline, base, quote='`')}")
    lines = [title, "", _verdict_line(report), ""] + _markdown_facts(report)
    order = scenarios_by_severity(report)
    lines += _markdown_comparison(report, order) + _markdown_newly_failing(report, report_path)
    lines += _markdown_measures(report, order)
    context = aggregates_lines(report)
    if context:
        lines += _details("Context: interquartile mean of return and probability of improvement (not the verdict)",
                          context)
    more = power_lines(report)[2:] + [headline(report, base)]
    lines += _details("Power and settings", [f"- {line}" for line in more])
    if report.errors:
        errors = [f"- `{e.id}` ({e.role}): {str(e.error).splitlines()[0][:300]}" for e in report.errors[:20]]
        if len(report.errors) > 20:
            errors.append(f"- ... and {len(report.errors) - 20} more (see `{report_path}`)")
        lines += _details(f"Errors ({len(report.errors)})", errors)
    text = "\n".join(lines)
    if len(text) > MARKDOWN_LIMIT:
        cut = text[:MARKDOWN_LIMIT].rsplit("\n", 1)[0]
        if cut.count("<details>") > cut.count("</details>"):
            cut += "\n\n</details>"
        text = cut + f"\n\n(cut to fit a pull-request comment: the whole report is `{report_path}`)\n"
    return text


def aggregates_lines(report: RegressReport) -> List[str]:
    """The context aggregates (:mod:`dv2s_gym.regress.aggregates`) as Markdown lines; none without them."""
    aggregates = report.aggregates
    if not aggregates:
        return []
    iqm = aggregates.get("return_iqm") or {}
    poi = aggregates.get("probability_of_improvement") or {}
    level = f"{100 * float(aggregates.get('confidence', 0.95)):g}%"
    return [f"Return, stratified bootstrap {level} intervals ({aggregates.get('resamples')} resamples within each "
            "scenario); the verdict is the paired failure test's.", "",
            f"- interquartile mean of the return: candidate {_interval(iqm.get('candidate'), False)}, baseline "
            f"{_interval(iqm.get('baseline'), False)}",
            f"- probability of improvement (a candidate episode's return above a baseline episode's, per scenario, "
            f"averaged): {_interval(poi, False)}"]


def write_json(report: RegressReport, path: Union[str, os.PathLike]) -> Path:
    """Write the report as JSON (atomic, sorted keys): the record's :meth:`~RegressReport.to_json`, the serialisation
    boundary."""
    return atomic_write_json(path, report.to_json())


def write_markdown(report: RegressReport, path: Union[str, os.PathLike], report_path: str = "report.json") -> Path:
    """Write the Markdown summary for a pull-request comment (paths relative to its folder)."""
    return atomic_write_text(path, _markdown(report, report_path, Path(path).parent))
