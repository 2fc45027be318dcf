"""A regression report to assert on: ``report.assert_no_regression()`` in a user's own tests.

:class:`RegressionReport` wraps the report :func:`~dv2s_gym.regress.runner.run_regression`
returns (a :class:`~dv2s_gym.regress.records.RegressReport`, or its JSON object) with the folder it was written to; :meth:`RegressionReport.failure_message` says, in a
few lines, why a verdict is not acceptable (which scenarios regressed, by how much, with which
p-values, which episodes newly fail, where the report is). The pytest plugin
(:mod:`dv2s_pytest`) fails tests with that message.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Union

from dv2s_gym.regress.records import RegressReport, ScenarioResult
from scenario_bank.errors import DV2SError
from scenario_bank.records import recorded

__all__ = ["RegressionReport", "RegressionFailed"]

SHOWN_EPISODES = 8
"""Newly failing episode ids named in a failure message; the rest are counted."""


class RegressionFailed(DV2SError, AssertionError):
    """A regression verdict that the caller did not accept (FAIL, or INCONCLUSIVE when not allowed)."""


def _pp(value: Any) -> str:
    return "?" if value is None else f"{100 * float(value):+.1f} pp"


def _pct(value: Any) -> str:
    return "?" if value is None else f"{100 * float(value):.0f}%"


def _fails_more(entry: ScenarioResult) -> bool:
    """The candidate fails more often than the baseline in this scenario entry."""
    table = (entry.comparison.table if entry.comparison is not None else None) or {}
    return table.get("candidate_only", 0) > table.get("baseline_only", 0)


class RegressionReport(Mapping[str, Any]):
    """A ``dv2s-regress`` report (read it like the dict) plus where it was written.

    Attributes:
        data: the report's JSON object.
        report: the report's record (:class:`~dv2s_gym.regress.records.RegressReport`).
        out_dir: the run's folder (``report.json``, ``report.md``, ``report.html``, traces).
    """

    def __init__(self, data: RegressReport, out_dir: Union[str, os.PathLike, None] = None) -> None:
        self.data: Dict[str, Any] = data.to_dict()
        self.report = data
        self.out_dir = None if out_dir is None else Path(out_dir)

    # Mapping interface: report["scenarios"], report.get("errors"), ...
    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    @property
    def verdict(self) -> Optional[str]:
        """``"PASS"``, ``"FAIL"``, ``"INCONCLUSIVE"``, ``"ERROR"``, or ``None`` without a baseline."""
        return self.report.verdict

    @property
    def regressed(self) -> List[str]:
        """Scenarios whose verdict is FAIL."""
        return list(self.report.regressed or ())

    @property
    def newly_failing(self) -> List[str]:
        """Episode ids (``"<scenario>/<seed>"``) the candidate fails and the baseline does not."""
        return list(self.report.newly_failing or ())

    @property
    def path(self) -> Optional[Path]:
        """The report to read first: ``report.html`` if written, else ``report.md`` or ``report.json``."""
        if self.out_dir is None:
            return None
        for name in ("report.html", "report.md", "report.json"):
            if (self.out_dir / name).is_file():
                return self.out_dir / name
        return self.out_dir / "report.json"

    def failure_message(self, allow_inconclusive: bool = True) -> Optional[str]:
        """Why this report's verdict is not acceptable, or ``None`` when it is.

        FAIL and ERROR (an episode ended in an error) are never acceptable; INCONCLUSIVE only with
        ``allow_inconclusive``; a report without a verdict (no baseline) is not acceptable, since
        nothing was compared.
        """
        verdict = self.verdict
        if verdict == "PASS" or (verdict == "INCONCLUSIVE" and allow_inconclusive):
            return None
        report = self.report
        candidate = report.candidate.spec if report.candidate is not None and "spec" in report.candidate.to_dict() else "?"
        baseline = report.baseline.spec if report.baseline is not None else None
        where = f"report: {self.path}" if self.path is not None else ""
        if verdict is None:
            return f"dv2s regression: {candidate!r} was run without a baseline, so there is no verdict; {where}"
        errors = report.errors or ()
        if verdict == "ERROR":
            lines = [f"dv2s regression ERROR: {candidate!r} against {baseline!r}: {len(errors)} episode(s) ended in "
                     "an error, so the run cannot be judged"]
            lines += [f"  {e.id} ({e.role}): {e.first_line[:200]}" for e in errors[:SHOWN_EPISODES]]
            if len(errors) > SHOWN_EPISODES:
                lines.append(f"  and {len(errors) - SHOWN_EPISODES} more")
            if where:
                lines.append(f"  {where}")
            return "\n".join(lines)
        lines = [f"dv2s regression {verdict}: {candidate!r} against {baseline!r}"]
        scenarios = report.scenarios or {}
        if verdict == "FAIL":
            named = self.regressed or [name for name, entry in scenarios.items() if _fails_more(entry)]
            label = "regressed on" if self.regressed else "failing more often (pooled FAIL) on"
            lines[0] += f" {label} {', '.join(named) if named else 'the pooled scenarios'}"
            for name in named:
                lines.append("  " + self._scenario_line(name, _or_empty(scenarios.get(name))))
        overall = report.overall.comparison if report.overall is not None else None
        if overall is not None and overall.reason:
            lines.append(f"  overall: {overall.reason}")
        if verdict == "INCONCLUSIVE":
            lines.append("  the runs cannot tell within the margin: run more episodes, widen the margin, or allow "
                         "INCONCLUSIVE (allow_inconclusive=True)")
        newly = self.newly_failing
        if newly:
            shown = ", ".join(newly[:SHOWN_EPISODES])
            more = f" and {len(newly) - SHOWN_EPISODES} more" if len(newly) > SHOWN_EPISODES else ""
            lines.append(f"  newly failing episodes: {shown}{more}")
        if errors:
            lines.append(f"  {len(errors)} episode(s) ended in errors")
        if where:
            lines.append(f"  {where}")
        return "\n".join(lines)

    @staticmethod
    def _scenario_line(name: str, entry: ScenarioResult) -> str:
        comparison = entry.comparison
        difference = (comparison.difference if comparison is not None else None) or {}

        def rate(role: str) -> Optional[float]:
            summary = entry.summary(role)
            return ((summary.failure_rate if summary is not None else None) or {}).get("value")

        candidate, baseline = rate("candidate"), rate("baseline")
        p_value, p_adjusted = (comparison.p_value, comparison.p_adjusted) if comparison is not None else (None, None)
        p_text = "" if p_value is None else f", p = {p_value:.3g}" + (
            "" if p_adjusted is None else f" (adjusted {p_adjusted:.3g})")
        return (f"{name}: failure rate {_pct(candidate)} vs {_pct(baseline)}, difference {_pp(difference.get('value'))} "
                f"[{_pp(difference.get('low'))}, {_pp(difference.get('high'))}]{p_text}")

    def assert_no_regression(self, allow_inconclusive: bool = True) -> "RegressionReport":
        """Raise :class:`RegressionFailed` (an ``AssertionError``) unless the verdict is acceptable."""
        message = self.failure_message(allow_inconclusive)
        if message is not None:
            raise RegressionFailed(message)
        return self

    def __repr__(self) -> str:
        return f"RegressionReport(verdict={self.verdict!r}, regressed={self.regressed!r}, out_dir={str(self.out_dir)!r})"


def _or_empty(entry: Optional[ScenarioResult]) -> ScenarioResult:
    """``entry``, or an empty scenario result when there is none or it holds nothing."""
    return entry if recorded(entry) else ScenarioResult()
