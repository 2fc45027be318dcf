"""The ``dv2s loop`` report: ``report.json`` (schema ``dv2s-loop`` version 1) and ``report.md``.

``report.json`` is :meth:`dv2s_gym.mining.loop.LoopReport.to_json`::

    {"schema": "dv2s-loop", "schema_version": 1, "out", "settings", "policy": final policy spec,
     "rounds": [{"round", "policy": spec it started from, "new_policy": fine-tuned spec,
                 "timings": {step: seconds},
                 "steps": {"mine": {"episodes", "errors", "failures", "failures_against_policy", "clusters",
                                    "conversions": {status: n}, "rejected_reasons", "kept": [{"cluster",
                                    "scenario", "reproduction"}], "folder"},
                           "split": {"fine_tune", "held_out", "fine_tune_clusters", "held_out_clusters", "groups"},
                           "before": {"episodes"},
                           "fine_tune": {"model", "scenarios", "mined_upweighted", "steps"},
                           "after": {"pairs", "errors", "before": Rate, "after": Rate, "relative_drop",
                                     "relative_drop_interval", "table", "mcnemar_p", "per_scenario"},
                           "regress": {"verdict", "reason", "episodes", "new_failure_rate", "old_failure_rate",
                                       "difference", "p_value", "regressed", "report"},
                           "skipped": reason (only when nothing was kept)}}]}

``Rate`` is ``{"k", "n", "rate", "low", "high"}`` (Wilson 95 %). A round missing a step has not
finished it yet (the loop was stopped; rerunning resumes it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

__all__ = ["write_loop_reports", "render_markdown"]


def _rate(r: Optional[Mapping[str, Any]]) -> str:
    if not r or r.get("rate") is None:
        return "-"
    return f"{r['k']}/{r['n']} = {r['rate']:.2f} [{r['low']:.2f}, {r['high']:.2f}]"


def _summary_rate(r: Optional[Mapping[str, Any]]) -> str:
    if not r:
        return "-"
    return f"{r.get('value', 0):.3f} [{r.get('low', 0):.3f}, {r.get('high', 0):.3f}]"


_ORDER = ("mine", "split", "before", "fine_tune", "after", "regress")


def _seconds(timings: Mapping[str, Any]) -> str:
    steps = sorted(timings, key=lambda s: _ORDER.index(s) if s in _ORDER else len(_ORDER))
    return ", ".join(f"{step} {float(timings[step]):.0f} s" for step in steps) or "-"


def render_markdown(report: Mapping[str, Any]) -> str:
    """The Markdown rendering of a loop report."""
    settings = report.get("settings", {})
    lines: List[str] = [
        "# dv2s loop", "",
        f"Started from `{settings.get('policy')}`; final policy `{report.get('policy')}`.", "",
        f"Per round: mining budget {settings.get('budget')} episodes ({settings.get('sampler')} sampler), "
        f"{settings.get('holdout_fraction')} of the mined clusters held out, {settings.get('k_eval')} evaluation seeds "
        f"per held-out scenario, fine-tuning {settings.get('fine_tune_steps')} steps (mined scenarios drawn with "
        f"probability {settings.get('mined_share')}), regression test on the starting bank with "
        f"{settings.get('regress_episodes')} seeds per scenario (margin {settings.get('margin')}).", "",
        "| round | failures mined (against the policy) / episodes | clusters | kept | fine-tune / held-out scenarios "
        "| held-out failure rate before | after | relative drop | McNemar p | rest of the bank |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for record in report.get("rounds", []):
        steps = record.get("steps", {})
        mine, split, after, regress = (steps.get(k) or {} for k in ("mine", "split", "after", "regress"))
        drop = after.get("relative_drop")
        interval = after.get("relative_drop_interval") or [None, None]
        drop_text = "-" if drop is None else f"{drop:.0%}" + (
            f" [{interval[0]:.0%}, {interval[1]:.0%}]" if interval[0] is not None else "")
        p_value = after.get("mcnemar_p")
        lines.append(
            f"| {record.get('round')} | {mine.get('failures', '-')} ({mine.get('failures_against_policy', '-')}) / "
            f"{mine.get('episodes', '-')} | {mine.get('clusters', '-')} | {len(mine.get('kept', []))} | "
            f"{len(split.get('fine_tune', []))} / {len(split.get('held_out', []))} | {_rate(after.get('before'))} | "
            f"{_rate(after.get('after'))} | {drop_text} | {'-' if p_value is None else f'{p_value:.3g}'} | "
            f"{regress.get('verdict') or steps.get('skipped') or '-'} |")
    for record in report.get("rounds", []):
        steps = record.get("steps", {})
        lines += ["", f"## Round {record.get('round')}", "",
                  f"- policy: `{record.get('policy')}` -> `{record.get('new_policy', '-')}`",
                  f"- timings: {_seconds(record.get('timings', {}))}"]
        if steps.get("skipped"):
            lines.append(f"- skipped: {steps['skipped']}")
        mine = steps.get("mine") or {}
        if mine:
            lines.append(f"- mining ({mine.get('folder')}): {mine.get('episodes')} episodes, {mine.get('failures')} "
                         f"failures ({mine.get('failures_against_policy')} avoidable by the reference driver), "
                         f"{mine.get('clusters')} clusters, conversions {mine.get('conversions')}, "
                         f"{mine.get('errors')} episode errors")
            for reason in mine.get("rejected_reasons", [])[:5]:
                lines.append(f"  - rejected: {reason}")
        split = steps.get("split") or {}
        if split:
            lines.append(f"- split by cluster ({split.get('groups')} groups): fine-tune "
                         f"{', '.join(split.get('fine_tune', [])) or 'none'}; held out "
                         f"{', '.join(split.get('held_out', [])) or 'none'}")
        tuned = steps.get("fine_tune") or {}
        if tuned:
            lines.append(f"- fine-tuned {tuned.get('steps')} steps on {tuned.get('scenarios')} scenarios "
                         f"({tuned.get('mined_upweighted')} mined, upweighted): `{tuned.get('model')}`")
        after = steps.get("after") or {}
        if after:
            table = after.get("table", {})
            lines.append(f"- held-out episodes: {after.get('pairs')} pairs ({after.get('errors')} with errors left "
                         f"out); before {_rate(after.get('before'))}, after {_rate(after.get('after'))}; paired "
                         f"table: both failed {table.get('both_fail')}, only before {table.get('before_only')}, "
                         f"only after {table.get('after_only')}, neither {table.get('neither')}")
            per = after.get("per_scenario") or {}
            if per:
                lines += ["", "| held-out scenario | episodes | failed before | failed after |", "|---|---|---|---|"]
                lines += [f"| {name} | {row['n']} | {row['before']} | {row['after']} |" for name, row in per.items()]
                lines.append("")
        regress = steps.get("regress") or {}
        if regress:
            lines.append(f"- regression test on the starting bank ({regress.get('episodes')} paired episodes): "
                         f"**{regress.get('verdict')}** - {regress.get('reason')}; failure rate new "
                         f"{_summary_rate(regress.get('new_failure_rate'))}, old "
                         f"{_summary_rate(regress.get('old_failure_rate'))}; report `{regress.get('report')}`")
    return "\n".join(lines) + "\n"


def _html(report: Mapping[str, Any], markdown: str) -> Optional[str]:
    """An HTML page when a renderer for loop reports exists (the mining report's module), else ``None``."""
    try:
        from dv2s_gym.mining import html as mining_html  # type: ignore[attr-defined]
    except ImportError:
        return None
    render = getattr(mining_html, "render_loop_html", None)
    return render(report) if render is not None else None


def write_loop_reports(report: Mapping[str, Any], out: Path) -> Dict[str, Path]:
    """Write ``report.json``, ``report.md`` (and ``report.html`` when available) atomically; returns their paths."""
    from scenario_bank.atomic import atomic_write_json, atomic_write_text

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": atomic_write_json(out / "report.json", dict(report), indent=1) or out / "report.json"}
    markdown = render_markdown(report)
    atomic_write_text(out / "report.md", markdown)
    paths["md"] = out / "report.md"
    page = _html(report, markdown)
    if page is not None:
        atomic_write_text(out / "report.html", page)
        paths["html"] = out / "report.html"
    return {key: Path(value) for key, value in paths.items()}
