"""The loop's measurements by ``dv2s regress``: start, fine-tuned and control on the untouched scenario set
(:func:`evaluate_untouched`) and the ``regress`` step, the fine-tuned policy against the round's start on the
starting bank's scenarios (:func:`regress_step`), with their records."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence

from dv2s_gym.loop.errored import errored_episodes
from dv2s_gym.loop.record import RegressComparison, RegressSummary, SplitRecord, UntouchedComparison
from dv2s_gym.loop.state import RunningLoop
from dv2s_gym.regress import runner
from dv2s_gym.regress.records import PairedComparison, RegressReport, ScenarioResult, Summary
from dv2s_gym.regress.runner import BaselineReport, RegressSettings
from dv2s_gym.workers.settings import WorkerSettings
from policies.evaluation import EVAL_SEED_BASE

__all__ = ["UNTOUCHED_BANK", "untouched_settings", "evaluate_untouched", "regress_step"]


UNTOUCHED_BANK = Path(__file__).resolve().parent / "untouched"
"""The scenario set no loop mines or fine-tunes on: a bank folder of scripts written by others for Scenic's
CARLA model (its ``SOURCES.md`` names them and their licence)."""


def untouched_settings(seeds: int, env_config: Mapping[str, Any], margin: float,
                       bank_dir: Optional[os.PathLike | str] = None):
    """The regression settings of the untouched set: ``bank_dir`` (default :data:`UNTOUCHED_BANK`), ``seeds``
    seeds per scenario from ``EVAL_SEED_BASE``, the policy's ``env_config`` and the loop's ``margin``."""
    return RegressSettings(bank_dir=str(Path(bank_dir or UNTOUCHED_BANK).resolve()), episodes=seeds,
                           seed=EVAL_SEED_BASE, margin=margin, env_config=dict(env_config))


def evaluate_untouched(start: str, fine_tuned: str, control: Optional[str], *, settings: Any, out: Path,
                       workers: int, progress: bool) -> UntouchedComparison:
    """Start, fine-tuned and control on the untouched scenario set (:func:`untouched_settings`: its bank, its
    seeds per scenario, the env config and margin) with ``dv2s regress``: fine-tuned
    against start (``out/vs_start``), then the control against the fine-tuned policy's episodes of that run
    (``out/vs_control``: only the control runs). Failure rates, stall rates and mean speeds per policy, and
    the two comparisons' verdicts, differences and p-values."""
    first = RegressReport.from_json(runner.run_regression(fine_tuned, start, settings,
                                                          workers=WorkerSettings(workers=workers),
                                                          out_dir=out / "vs_start", progress=progress))
    overall = first.overall if first.overall is not None else ScenarioResult()
    policies = {"start": _measures(overall.baseline), "fine_tuned": _measures(overall.candidate)}
    result = UntouchedComparison(scenarios=tuple((first.bank.scenarios if first.bank is not None else None) or ()),
                                 seeds=settings.episodes, policies=policies,
                                 fine_tuned_vs_start=_comparison(first, out / "vs_start" / "report.json"),
                                 errored=_regress_errored(first, {"baseline": "start", "candidate": "fine_tuned"}))
    if control is not None:
        # a measurement, not a gate: the fine-tuned policy is the reference whatever its own verdict was
        baseline = BaselineReport(out / "vs_start" / "report.json", role="candidate", accept_failed=True)
        second = RegressReport.from_json(runner.run_regression(control, baseline, settings,
                                                               workers=WorkerSettings(workers=workers),
                                                               out_dir=out / "vs_control", progress=progress))
        result = result.replace(
            policies={**policies,
                      "control": _measures(second.overall.candidate if second.overall is not None else None)},
            control_vs_fine_tuned=_comparison(second, out / "vs_control" / "report.json"),
            errored={**result.errored, **_regress_errored(second, {"candidate": "control"})})
    return result


def regress_step(loop: RunningLoop, new_policy: str, current: str, round_dir: Path,
                 split: SplitRecord) -> RegressSummary:
    """The ``regress`` step: the fine-tuned policy against the round's start on the starting bank's scenarios."""
    s = loop.settings
    settings = RegressSettings(bank_dir=loop.bank, scenarios=loop.start_names, episodes=s.regress_episodes,
                               seed=EVAL_SEED_BASE, margin=s.margin, env_config=loop.env_config)
    report = runner.run_regression(new_policy, current, settings, workers=WorkerSettings(workers=loop.workers),
                                   out_dir=round_dir / "regress", progress=loop.progress)
    summary = _regress_summary(report, round_dir / "regress" / "report.json", split.held_out_family_names)
    return summary.replace(errored=_regress_errored(report, {"baseline": "start", "candidate": "fine_tuned"}))


def _regress_errored(report: RegressReport, roles: Mapping[str, str]) -> Dict[str, Dict[str, Any]]:
    """The errored episodes of a ``dv2s regress`` report (a :class:`~dv2s_gym.regress.records.RegressReport`) per
    policy: ``roles`` maps its roles (``candidate``, ``baseline``) to the loop's names for them
    (:func:`errored_episodes`' form)."""
    report = RegressReport.from_json(report)
    found: Dict[str, Dict[str, Any]] = {}
    for role, name in roles.items():
        found[name] = errored_episodes([e.result(role).replace(scenario=e.scenario)
                                        for e in report.episodes or () if e.errored(role)])
    return found


def _regress_summary(report: RegressReport, path: Path, parents: Sequence[str] = ()) -> RegressSummary:
    """The regression step's record; ``parents``: scenarios whose own results are kept apart (the held-out
    families' parents, never fine-tuned on: the regression test's view beyond the fine-tuning mix)."""
    report = RegressReport.from_json(report)
    overall = report.overall if report.overall is not None else ScenarioResult()
    per_scenario = report.scenarios or {}
    comparison = overall.comparison if overall.comparison is not None else PairedComparison()

    def rate(role: str) -> Optional[Mapping[str, Any]]:
        summary = overall.summary(role)
        return summary.failure_rate if summary is not None else None

    def measures(summary: Optional[Summary]) -> Dict[str, Any]:
        summary = summary if summary is not None else Summary()
        return {"failure_rate": summary.failure_rate, "stall_rate": summary.rate("stall"),
                "mean_speed": summary.mean_speed}

    return RegressSummary(
        verdict=report.verdict, reason=comparison.reason, episodes=comparison.n,
        new_failure_rate=rate("candidate"), old_failure_rate=rate("baseline"),
        difference=comparison.difference, p_value=comparison.p_value,
        regressed=tuple(report.regressed or ()), report=str(Path(path).resolve()),
        held_out_parents={name: {role: measures(per_scenario[name].summary(side))
                                 for role, side in (("new", "candidate"), ("old", "baseline"))}
                          for name in parents if name in per_scenario})


def _measures(summary: Optional[Summary]) -> Dict[str, Any]:
    summary = summary if summary is not None else Summary()
    return {"episodes": summary.episodes, "errors": summary.errors,
            "failure_rate": summary.failure_rate, "stall_rate": summary.rate("stall"),
            "collision_rate": summary.rate("collision"), "mean_speed": summary.mean_speed}


def _comparison(report: RegressReport, path: Path) -> RegressComparison:
    overall = report.overall if report.overall is not None else ScenarioResult()
    comparison = overall.comparison if overall.comparison is not None else PairedComparison()
    return RegressComparison(verdict=report.verdict, reason=comparison.reason, episodes=comparison.n,
                             difference=comparison.difference, p_value=comparison.p_value,
                             report=str(Path(path).resolve()))
