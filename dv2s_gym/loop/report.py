"""The ``dv2s loop`` report: ``report.json`` (schema ``dv2s-loop`` version 1), ``report.md`` and ``report.html``.

``report.json`` is :meth:`dv2s_gym.loop.run.LoopReport.to_json`::

    {"schema": "dv2s-loop", "schema_version": 1, "out", "settings", "policy": the last fine-tuned policy's spec,
     "recommendation": {"policy": the spec to use, "verdict": ACCEPTED | REJECTED | NOT ACCEPTED, "round",
                        "candidate", "reason", "decided_by": the test that decided, "sentence", "exit_code",
                        "too_small": why the round was too small to judge, or None}
                        (:mod:`dv2s_gym.loop.verdict`),
     "rounds": [{"round", "policy": spec it started from, "new_policy": fine-tuned spec,
                 "next_policy": the spec the next round starts from (the one the verdict on the rounds so far
                 recommends), "next_policy_reason",
                 "timings": {step: seconds},
                 "control_policy": the control arm's spec (with a control),
                 "steps": {"mine": {"episodes", "errors", "errored", "failures", "failures_against_policy", "clusters",
                                    "clusters_not_converted", "clusters_not_kept", "clusters_reference_failed"
                                    (clusters no conversion tried whose every failing scene the reference driver
                                    failed too: no exact replay), "conversions": {status: n},
                                    "replays": {status: n}, "rejected_reasons" (every failed check of each
                                    rejected conversion, at most 40), "rejected_reason_count",
                                    "kept": [{"cluster", "scenario", "reproduction", "replay" (exact replays:
                                              True), "parent" (exact replays)}], "folder"},
                           "split": {"by": "family", "fine_tune", "held_out", "fine_tune_clusters",
                                     "held_out_clusters", "fine_tune_families", "held_out_families", "groups",
                                     "moved_to_fine_tune"},
                           "reference": {"reference", "episodes", "kept", "excluded": [[scenario, seed]]
                                         (held-out episodes the reference driver failed or errored on, left out of
                                         every rate and test), "failed", "errored", "by_scenario",
                                         "excluded_families"} (loop.reference_gate),
                           "before": {"episodes" (those the reference driver passed), "errored"},
                           "fine_tune" and "control": {"model", "method": "ppo" | "dagger", "scenarios",
                                         "mined_upweighted", "mined_left_out", "steps", "families" (every
                                         family in the arm's mix: later rounds keep them on the fine-tuning side),
                                         "reward_weights" (ppo; None for dagger),
                                         "env_config": the fine-tuning env's config,
                                         "reference", "agreement", "resumed" (dagger only)},
                           "after": {"pairs", "errors", "before": Rate (start), "after": Rate (fine-tuned),
                                     "control": Rate, "relative_drop", "relative_drop_interval" (resampling
                                     "relative_drop_interval_unit" "family", "relative_drop_interval_units" of
                                     them), "table", "mcnemar_p" (fine-tuned vs start, per pair: "mcnemar_unit"),
                                     "pairs_per_family", "per_scenario",
                                     "vs_control": {"pairs", "errors", "relative_drop", "table": {"both_fail",
                                                    "fine_tuned_only", "control_only", "neither"}, "mcnemar_p",
                                                    "per_scenario": {scenario: control failures}},
                                     "failure_types": {"start" | "control" | "fine_tuned": {type: n}},
                                     "min_episodes", "min_families", "heldout_families" (with a tested pair),
                                     "sampled_families", "heldout_scenarios",
                                     "underpowered": why no drop or test is reported (only below
                                     min_episodes pairs or min_families families; then the drop and
                                     p-values are None),
                                     "significantly_worse": {"start" | "control": is the fine-tuned policy
                                         significantly worse on the held-out families
                                         (:func:`dv2s_gym.loop.verdict.heldout_worse`: {"against", "test",
                                         "worse", "families", "pairs", "fine_tuned_only", "other_only", "p_value",
                                         "worse_families", "reason", "family_harm": the held-out families'
                                         harm rule at the margin (:func:`dv2s_gym.loop.verdict.family_harm`:
                                         {"margin", "rule", "families", "harmed", "non_inferior"})}; None when
                                         not tested), "margin": the margin of that rule},
                           "untouched": {"scenarios", "seeds", "policies": {"start" | "control" | "fine_tuned":
                                         {"episodes", "errors", "failure_rate", "stall_rate", "collision_rate",
                                          "mean_speed"}} (dv2s regress summaries), "fine_tuned_vs_start" and
                                         "control_vs_fine_tuned": {"verdict", "reason", "episodes", "difference",
                                         "p_value", "report"}},
                           "regress": {"verdict", "reason", "episodes", "new_failure_rate", "old_failure_rate",
                                       "difference", "p_value", "regressed", "report", "held_out_parents":
                                       {scenario: {"new" | "old": {"failure_rate", "stall_rate", "mean_speed"}}}},
                           "skipped": reason (only when nothing was kept)}}],
     "final_vs_start": (with two or more regression-tested rounds) {"start", "final", "rounds": [first, last],
                        "verdict", "reason", "episodes", "new_failure_rate", "old_failure_rate", "difference",
                        "p_value", "regressed", "report"} or {"error"}}

``final_vs_start`` compares the final policy with the starting one on the starting bank without running
anything: each round's regression test runs the same starting-bank scenarios and seeds, so the first tested
round's baseline episodes (the starting policy) are paired with the last tested round's candidate episodes
(the final policy) and judged by the regression test's own rule (:func:`final_vs_start`); the paired report is
``final_vs_start/report.json`` in the loop folder.

``errored`` counts the episodes that errored (no rate or test counts them; e.g. a scene the scenario's
sampler could not produce): in ``mine`` and ``before`` ``{"episodes", "scenarios": {scenario: n}, "messages":
{scenario: [{"message", "count"}]: every distinct error, the most frequent first; the reports list 5 and count
the rest}, "examples": {scenario: its first error}}`` (:func:`dv2s_gym.loop.errored.errored_episodes`);
in ``after`` the same per policy
(``fine_tuned``, ``control``), in ``untouched`` and ``regress`` per policy (``start``, ``fine_tuned``, and
``control`` in ``untouched``). The log warns of them after each step and ``report.md`` lists them per round.

``Rate`` is ``{"k", "n", "rate", "low", "high"}`` (Wilson 95 %). ``report.html`` also shows, per round, the
clips of the kept mined scenarios (the bank entry's videos, else the mining run's): each failure's clip beside a
clip of its converted script driven by the same policy on one reproduction episode, captioned with the scenario,
the seed and whether (and how) that episode failed; an exact replay shows only its failure clip, saying why (no
converted script, or the script converted from it was rejected, with the judge's reason in short); a kept entry
without any clip says why (an extra exact replay of a cluster no conversion tried is not filmed). A round missing
a step has not
finished it yet (the loop was stopped; rerunning resumes it).
"""

from __future__ import annotations

import json
import os
import re
from dv2s_gym.mining.conversion.files import CONVERSION_DIR, ENTRY_CONVERTED_VIDEO, ENTRY_VIDEO, cluster_slug
from dv2s_gym.mining.conversion.record import ConversionStatus
from dv2s_gym.loop.errored import merged_messages, messages_text
from dv2s_gym.loop.record import (
    ControlTable, ErroredEpisodes, FinalVsStart, HeldOutComparison, MinedEntry, MiningSummary, PairedTable, ReferenceGate, RegressSummary,
    RoundRecord, RoundSteps, SplitRecord, UntouchedComparison, recorded)
from dv2s_gym.mining.report_text import by_type_text, clip_caption
from dv2s_gym.loop.verdict import (ACCEPTED, HELDOUT_ALPHA, Recommendation, evidence_floor_note,
                                         judge_round, recommendation)
from dv2s_gym.regress.records import BankInfo, PairedComparison, PairedEpisode, Summary
from dv2s_gym.regress.report import build_report, load_report, write_json
from html import escape
from pathlib import Path
from policies.card_record import FineTuneMethod
from policies.stats import Rate
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.entries import SIDECAR, read_json
from typing import Any, Dict, List, Mapping, Optional

__all__ = ["rate_text", "write_loop_reports", "render_markdown", "render_html", "round_summary", "round_clips", "final_vs_start",
           "with_cross_round_checks", "FINAL_VS_START_DIR", "errored_note", "errored_text", "reference_gate_text"]

FINAL_VS_START_DIR = "final_vs_start"
"""Folder (in the loop folder) of the final-vs-starting-policy paired regression report."""


def rate_text(rate: Optional[Rate]) -> str:
    """A held-out failure rate as ``k/n = rate [low, high]`` (:meth:`Rate.text`; ``-``: none)."""
    return "-" if rate is None else rate.text()


def _summary_rate(r: Optional[Mapping[str, Any]]) -> str:
    if not r:
        return "-"
    return f"{r.get('value', 0):.3f} [{r.get('low', 0):.3f}, {r.get('high', 0):.3f}]"


def _weights(weights: Optional[Mapping[str, Any]]) -> str:
    if weights is None:
        return "-"
    if not weights:
        return "none"
    return ", ".join(f"{name} {float(value):g}" for name, value in sorted(weights.items()))


def _regress_report_path(stored: str, folder: Optional[Path]) -> Path:
    """Where a round's regression report is: ``stored`` as ``loop.json`` has it (an absolute path), read in the
    loop folder ``folder`` when given (its ``round_<n>/...`` part), so that a loop folder moved elsewhere is read
    where it is now."""
    path = Path(stored)
    if folder is None:
        return path
    parts = path.parts
    rounds = [index for index, part in enumerate(parts) if re.fullmatch(r"round_\d+", part)]
    candidates = ([Path(folder).joinpath(*parts[rounds[-1]:])] if rounds else []) + [path]
    return next((candidate for candidate in candidates if candidate.is_file()), candidates[0])


def final_vs_start(report: Mapping[str, Any], out: Optional[Path] = None,
                   folder: Optional[Path] = None) -> Optional[FinalVsStart]:
    """The final policy against the starting policy on the starting bank, from the rounds' regression reports.

    ``None`` unless two or more rounds finished their regression test. The first tested round's baseline
    (the starting policy: a skipped round does not change the policy) and the last tested round's candidate
    (the final policy) ran the same scenarios and seeds; their episodes are paired by id and judged as
    ``dv2s regress`` does (:func:`dv2s_gym.regress.report.build_report`). With ``out`` the paired report is
    written to ``out/final_vs_start/report.json``. A report that cannot be read, or a starting-bank scenario
    that changed between the rounds, gives a record holding only its ``error`` instead (and the verdict is then NOT
    ACCEPTED).
    ``folder``: the loop folder the reports are read from (default ``out``; see :func:`_regress_report_path`).
    """
    tested = [r for r in _rounds(report) if r.steps.regress is not None and r.steps.regress.report]
    if len(tested) < 2:
        return None
    first, last = tested[0], tested[-1]
    try:
        folder = folder if folder is not None else out
        start = load_report(_regress_report_path(first.steps.regress.report, folder))
        final = load_report(_regress_report_path(last.steps.regress.report, folder))
    except Exception as error:  # noqa: BLE001 - a missing or foreign report is a line of the loop report
        return FinalVsStart.failed(f"cannot read the rounds' regression reports: {(str(error).splitlines() or [''])[0]}")
    start_bank = start.bank if start.bank is not None else BankInfo()
    final_bank = final.bank if final.bank is not None else BankInfo()
    names = list(start_bank.scenarios or ())
    hashes = [start_bank.hashes or {}, final_bank.hashes or {}]
    changed = [n for n in names if hashes[0].get(n) != hashes[1].get(n)]
    if changed or names != list(final_bank.scenarios or ()):
        return FinalVsStart.failed(f"the starting bank differs between round {first.round} and round "
                                   f"{last.round} ({', '.join(changed[:3]) or 'scenario list'}); no paired comparison")
    baseline = {e.id: e.baseline for e in start.episodes or ()}
    episodes = [PairedEpisode(id=e.id, scenario=e.scenario, seed=e.seed, candidate=e.candidate,
                              baseline=baseline[e.id])
                for e in final.episodes or () if baseline.get(e.id) is not None]
    if not episodes:
        return FinalVsStart.failed(f"round {first.round} and round {last.round} share no regression episode")
    paired = build_report(bank=final.bank, settings=final.settings, candidate=final.candidate,
                          baseline=start.baseline, episodes=episodes)
    path = None
    if out is not None:
        path = write_json(paired, Path(out) / FINAL_VS_START_DIR / "report.json")
    overall = paired.overall
    comparison = overall.comparison if overall.comparison is not None else PairedComparison()

    def failure_rate(summary: Optional[Summary]) -> Optional[Mapping[str, Any]]:
        return summary.failure_rate if summary is not None else None

    return FinalVsStart(start=start.baseline.spec if start.baseline is not None else None,
                        final=final.candidate.spec if final.candidate is not None else None,
                        rounds=(first.round, last.round), verdict=paired.verdict,
                        reason=comparison.reason, episodes=comparison.n,
                        new_failure_rate=failure_rate(overall.candidate),
                        old_failure_rate=failure_rate(overall.baseline),
                        difference=comparison.difference, p_value=comparison.p_value,
                        regressed=tuple(paired.regressed or ()), report=str(path) if path is not None else None)


def with_cross_round_checks(report: Mapping[str, Any], out: Optional[Path] = None,
                            folder: Optional[Path] = None) -> Dict[str, Any]:
    """``report`` with the cross-round check (:func:`final_vs_start` over the rounds up to it) recorded in each
    round that its own tests accepted (``None`` before two rounds were regression-tested), and, with two or more
    tested rounds, the report's own ``final_vs_start`` (its paired report written under ``out``). A policy the
    check rejected is never the policy to use (:func:`dv2s_gym.loop.verdict.recommendation`)."""
    rounds = _rounds(report)
    for index, record in enumerate(rounds):
        judged = judge_round(record)
        if judged is not None and judged.verdict == ACCEPTED and not record.cross_round_checked:
            checked = final_vs_start({"rounds": rounds[:index + 1]}, folder=folder or out)
            rounds[index] = record.with_cross_round_check(checked)
    body = {**report, "rounds": [record.to_dict() for record in rounds]}
    if "final_vs_start" not in body:
        final = final_vs_start(body, out, folder)
        if final is not None:
            body["final_vs_start"] = final.to_dict()
    return body


def _final_line(final: Optional[FinalVsStart]) -> Optional[str]:
    """One sentence on the last fine-tuned policy against the starting one (None when there is no such
    comparison)."""
    if final is None:
        return None
    if final.error:
        return f"Fine-tuned policy against the starting policy on the starting bank: not compared ({final.error})."
    rounds = final.rounds or ("?", "?")
    return (f"Round {rounds[1]}'s fine-tuned policy `{final.final}` against the starting policy "
            f"`{final.start}` on the starting "
            f"bank ({final.episodes} paired episodes: round {rounds[0]}'s baseline episodes with round "
            f"{rounds[1]}'s candidate episodes, same scenarios and seeds): **{final.verdict}** - "
            f"{final.reason}; failure rate fine-tuned {_summary_rate(final.new_failure_rate)}, start "
            f"{_summary_rate(final.old_failure_rate)}"
            + (f"; regressed: {', '.join(final.regressed)}" if final.regressed else "")
            + (f"; report `{final.report}`" if final.report else "") + ".")


def _report_final(report: Mapping[str, Any]) -> Optional[FinalVsStart]:
    """The report's own cross-round check (``final_vs_start``), read into its record; ``None`` without one."""
    found = report.get("final_vs_start")
    return None if found is None else FinalVsStart.from_dict(found)


_ORDER = ("mine", "split", "reference", "before", "fine_tune", "control", "after", "untouched", "regress")


def _seconds(timings: Mapping[str, Any]) -> str:
    steps = sorted(timings, key=lambda s: _ORDER.index(s) if s in _ORDER else len(_ORDER))
    return ", ".join(f"{step} {float(timings[step]):.0f} s" for step in steps) or "-"


def _rounds(report: Mapping[str, Any]) -> List[RoundRecord]:
    """The rounds of a loop report's body (``report.json``'s ``rounds``), as records."""
    return [RoundRecord.from_dict(record) for record in report.get("rounds") or []]


def _round_row(record: RoundRecord) -> Dict[str, Any]:
    """The cells of a round's line in the summary tables (Markdown and HTML)."""
    steps = record.steps
    mine, split = steps.mine, steps.split if steps.split is not None else SplitRecord()
    regress = steps.regress if steps.regress is not None else RegressSummary()
    after = steps.after if steps.after is not None else HeldOutComparison()
    drop = after.relative_drop
    interval = after.relative_drop_interval or [None, None]
    drop_text = "-" if drop is None else f"{drop:.0%}" + (
        f" [{interval[0]:.0%}, {interval[1]:.0%}]" if interval[0] is not None else "")
    if after.underpowered:
        short = []
        if (after.pairs or 0) < (after.min_episodes or 0):
            short.append(f"{after.pairs} < {after.min_episodes} episodes")
        if after.heldout_families is not None and after.heldout_families < (after.min_families or 0):
            short.append(f"{after.heldout_families} < {after.min_families} families")
        drop_text = "not reported: " + ", ".join(short or ["too few held-out episodes"])
    p_value = after.mcnemar_p
    p_control = None if after.vs_control is None else after.vs_control.mcnemar_p
    return {
        "control": rate_text(after.control) if recorded(after.control) else "-",
        "p_control": "-" if p_control is None else f"{p_control:.3g}",
        "untouched": _untouched_cell(steps.untouched),
        "round": record.round, "failures": _recorded(mine, "failures"),
        "against": _recorded(mine, "failures_against_policy"), "episodes": _recorded(mine, "episodes"),
        "clusters": _recorded(mine, "clusters"), "kept": len({e.scenario for e in (mine.kept_entries if mine is not None else ())}),
        "split": f"{len(split.fine_tune_scenarios)} / {len(split.held_out_scenarios)}",
        "before": rate_text(after.before), "after": rate_text(after.after), "drop": drop_text,
        "p": "-" if p_value is None else f"{p_value:.3g}",
        "verdict": regress.verdict or steps.skipped or "-",
    }


def _recorded(record: Optional[MiningSummary], name: str) -> Any:
    """Field ``name`` of the mining step's record as recorded (``None`` when recorded as ``null``), ``"-"`` when the
    step did not record it or did not run."""
    if record is None:
        return "-"
    value = getattr(record, name)
    nulls = record.default_null_fields() if record.null_fields is None else record.null_fields
    return "-" if value is None and name not in nulls else value


def errored_text(errored: Mapping[str, Optional[ErroredEpisodes]]) -> str:
    """``"fine-tuned policy 3 (urban_pedestrian_crossing 3), control 1 (...)"``: errored episodes per policy (the
    mining step's without a policy's name), in words; empty when none errored."""
    labels = {"start": "starting policy ", "fine_tuned": "fine-tuned policy ", "control": "control ", "mine": ""}
    parts = []
    for role, found in errored.items():
        if found is not None and found.episodes:
            names = ", ".join(f"{name} {count}" for name, count in (found.scenarios or {}).items())
            parts.append(f"{labels.get(role, role + ' ')}{found.episodes}" + (f" ({names})" if names else ""))
    return ", ".join(parts)


def errored_note(errored: Optional[ErroredEpisodes]) -> str:
    """`` (3 episodes errored: urban_pedestrian_crossing 2, highway_cut_in_from_left 1)`` after an episode count
    that includes them (:func:`dv2s_gym.loop.errored.errored_episodes`); empty when none errored."""
    count = int(errored.episodes or 0) if errored is not None else 0
    if not count:
        return ""
    names = ", ".join(f"{name} {n}" for name, n in (errored.scenarios or {}).items())
    return f" ({count} episode{'s' if count != 1 else ''} errored" + (f": {names})" if names else ")")


def errored_by_stage(record: RoundRecord) -> List[tuple]:
    """``[(stage label, {policy: errored})]``: round ``record``'s errored episodes per step that ran
    (:func:`dv2s_gym.loop.errored.errored_episodes`' form; a JSON object is read with ``RoundRecord.from_dict``)."""
    steps = RoundRecord.from_dict(record).steps
    found = []
    if steps.mine is not None and steps.mine.errored is not None:
        found.append(("mining", {"mine": steps.mine.errored}))
    held: Dict[str, Any] = {}
    if steps.before is not None and steps.before.errored is not None:
        held["start"] = steps.before.errored
    held.update((steps.after.errored if steps.after is not None else None) or {})
    if held:
        found.append(("held-out", held))
    for step, label in ((steps.untouched, "untouched set"), (steps.regress, "regression test")):
        errored = step.errored if step is not None else None
        if errored:
            found.append((label, errored))
    return found


def _errored_total(record: RoundRecord) -> int:
    return sum(int(found.episodes or 0) for _, by in errored_by_stage(record) for found in by.values()
               if found is not None)


def _errored_lines(record: RoundRecord) -> List[str]:
    """The round's errored episodes per step and policy, naming the scenarios and, for each, its distinct error
    messages with their counts over the round's steps (the most frequent first, at most
    :data:`dv2s_gym.loop.errored.ERROR_MESSAGES_KEPT` listed, the rest counted)."""
    stages = errored_by_stage(record)
    if not stages:
        return []
    parts = [f"{label}: {errored_text(by) or 'none'}" for label, by in stages]
    total = _errored_total(record)
    lines = [f"- errored episodes (counted in no rate or test): " + ("**" if total else "") + "; ".join(parts)
             + ("**" if total else "")]

    merged = merged_messages([found for _, by in stages for found in by.values() if recorded(found)])
    lines += [f"  - `{name}`: {messages_text(merged, name)}" for name in merged]
    return lines


def round_summary(record: RoundRecord) -> str:
    """One plain-text line on round ``record`` (its JSON object is read with ``RoundRecord.from_dict``) for the
    terminal: held-out failure rates and the regression verdict."""
    record = RoundRecord.from_dict(record)
    row = _round_row(record)
    steps = record.steps
    if steps.skipped:
        return f"round {row['round']}: skipped: {steps.skipped}"
    errored = _errored_total(record)
    mined = errored_note(steps.mine.errored if steps.mine is not None else None)
    return (f"round {row['round']}: {row['failures']} failures mined in {row['episodes']} episodes{mined}, "
            f"{row['kept']} scenarios kept; held-out failure rate start {row['before']}, control {row['control']}, fine-tuned "
            f"{row['after']}; rest of the bank: {row['verdict']}"
            + (f"; {errored} episode(s) errored (see the report)" if errored else ""))


def _replays_text(settings: Mapping[str, Any]) -> str:
    """How many clusters beyond the converted ones a round keeps as exact replays, in words."""
    count = settings["max_replays"]
    if count == 0:
        return "no exact replays beyond the converted clusters"
    return f"{'every other cluster' if count is None else f'at most {count} other clusters'} kept as exact replays"


def _share(summary: Optional[Mapping[str, Any]], key: str) -> str:
    value = ((summary or {}).get(key) or {}).get("value")
    return "-" if value is None else f"{value:.2f}"


def _untouched_cell(untouched: Optional[UntouchedComparison]) -> str:
    """Failure rates start / control / fine-tuned on the untouched set, one cell."""
    if not recorded(untouched):
        return "-"
    policies = untouched.policies or {}
    return " / ".join(_share(policies.get(role), "failure_rate") for role in ("start", "control", "fine_tuned"))


def _untouched_lines(untouched: Optional[UntouchedComparison]) -> List[str]:
    """The untouched set's table (Markdown) and its two comparisons."""
    if not recorded(untouched):
        return []
    policies = untouched.policies or {}
    lines = [f"- untouched scenario set ({len(untouched.scenarios or ())} scripts written by others for "
             f"Scenic's CARLA model, never mined or fine-tuned on; {untouched.seeds} seeds each; "
             "dv2s regress statistics):", "",
             "| policy | episodes | failure rate | stall rate | collision rate | mean speed [m/s] |",
             "|---|---|---|---|---|---|"]
    for role, label in (("start", "start"), ("control", "control"), ("fine_tuned", "fine-tuned")):
        row = policies.get(role)
        if row is None:
            continue
        speed = (row.get("mean_speed") or {}).get("value")
        lines.append(f"| {label} | {row.get('episodes')} | {_summary_rate(row.get('failure_rate'))} | "
                     f"{_summary_rate(row.get('stall_rate'))} | {_summary_rate(row.get('collision_rate'))} | "
                     f"{'-' if speed is None else f'{speed:.1f}'} |")
    lines.append("")
    vacuous = untouched.vacuous()
    if vacuous:
        lines.append(f"- **WARNING: {vacuous}**")
    for comparison, label in ((untouched.fine_tuned_vs_start, "fine-tuned against start"),
                              (untouched.control_vs_fine_tuned, "control against fine-tuned")):
        if recorded(comparison):
            lines.append(f"- untouched, {label}: **{comparison.verdict}** - {comparison.reason}; "
                         f"report `{comparison.report}`")
    return lines


def _sources_text(after: HeldOutComparison) -> str:
    """`` from F families (S scenarios)`` of a held-out comparison, or nothing for one recorded without them."""
    if after.heldout_families is None:
        return ""
    families, scenarios = after.heldout_families, after.heldout_scenarios
    sampled = after.sampled_families
    untested = (f", {sampled - families} more with no tested pair" if sampled is not None and sampled > families
                else "")
    return (f" from {families} famil{'y' if families == 1 else 'ies'} ({scenarios} scenario"
            f"{'' if scenarios == 1 else 's'}{untested})")


def reference_gate_text(gate: ReferenceGate) -> str:
    """The reference step's outcome in one sentence (log and reports; a JSON object of one is read as a
    :class:`~dv2s_gym.loop.record.ReferenceGate`)."""
    gate = ReferenceGate.from_dict(gate)
    if not gate.excluded:
        return (f"the reference driver {gate.reference} passed all {gate.episodes} held-out episodes; "
                "none left out")
    scenarios = "; ".join(
        f"{name} {row['excluded']}/{row['episodes']} ("
        + ", ".join(f"{kind} {n}" for kind, n in sorted(row["failures"].items())) + ")"
        for name, row in (gate.by_scenario or {}).items() if row.get("excluded"))
    families = gate.excluded_families or ()
    return (f"{len(gate.excluded or ())} of {gate.episodes} held-out episodes left out because the reference "
            f"driver {gate.reference} did not pass them ({gate.failed} failed, {gate.errored} "
            f"errored): {scenarios}"
            + (f"; famil(ies) left out entirely: {', '.join(families)}" if families else ""))


def _reference_lines(gate: Optional[ReferenceGate]) -> List[str]:
    """The reference driver's pass over the held-out episodes: how many it did not pass, left out of every rate
    and test (loop.reference_gate)."""
    if not recorded(gate):
        return []
    text = reference_gate_text(gate)
    return [f"- held-out episodes the reference driver does not pass: " + (f"**{text}**" if gate.excluded
                                                                           else text)]


def _heldout_lines(after: Optional[HeldOutComparison]) -> List[str]:
    """The held-out comparison: start, control, fine-tuned, and what is (not) reported."""
    if not recorded(after):
        return []
    lines = []
    if after.underpowered:
        lines.append(f"- **WARNING: {after.underpowered}**")
    if not after.pairs:
        return lines + [f"- held-out episodes: none ran ({0 if after.errors is None else after.errors} with errors)"]
    table = after.table if after.table is not None else PairedTable()
    lines.append(f"- held-out episodes: {after.pairs} pairs{_sources_text(after)} ({after.errors} with "
                 f"errors left out); start {rate_text(after.before)}"
                 + (f", control {rate_text(after.control)}" if recorded(after.control) else "")
                 + f", fine-tuned {rate_text(after.after)}; paired fine-tuned vs start: both failed "
                 f"{table.both_fail}, only start {table.before_only}, only fine-tuned "
                 f"{table.after_only}, neither {table.neither}"
                 + ("" if after.mcnemar_p is None else f", exact two-sided McNemar p = {after.mcnemar_p:.3g}"))
    dependence = _dependence_line(after)
    if dependence:
        lines.append(dependence)
    kinds = after.failure_types
    if recorded(kinds):
        lines.append("- held-out failures by type: " + "; ".join(
            f"{label} {by_type_text(getattr(kinds, role))}"
            for role, label in (("start", "start"), ("control", "control"), ("fine_tuned", "fine-tuned"))
            if getattr(kinds, role) is not None))
    versus = after.vs_control
    if recorded(versus):
        table = versus.table if versus.table is not None else ControlTable()
        lines.append(f"- paired fine-tuned vs control: both failed {table.both_fail}, only control "
                     f"{table.control_only}, only fine-tuned {table.fine_tuned_only}, neither "
                     f"{table.neither}"
                     + ("" if versus.mcnemar_p is None else f", exact two-sided McNemar p = {versus.mcnemar_p:.3g}")
                     + ("" if versus.relative_drop is None
                        else f", relative drop against the control {versus.relative_drop:.0%}"))
    elif not after.control:
        lines.append("- no control arm in this round: a drop cannot be credited to the mined scenarios")
    for key, label in (("start", "the starting policy"), ("control", "the control")):
        test = after.held_out_test(key)
        if test is not None:
            lines.append(f"- fine-tuned policy against {label} on the held-out families: "
                         f"**{'significantly worse' if test.worse else 'not significantly worse'}** "
                         f"({test.reason}; {test.test})")
            harm = test.family_harm
            if harm is not None:
                lines.append(f"- held-out families against {label}, harm rule at the margin "
                             f"{100 * harm.margin:+.1f} pp (a family whose difference is worse blocks ACCEPTED): "
                             + ("**harm not ruled out in " + ", ".join(harm.harmed) + "**; " if harm.harmed
                                else "no family worse by more than the margin; ")
                             + "per family the difference (95% CI; non-inferiority at the margin, Holm over the "
                             f"families at one-sided {HELDOUT_ALPHA / 2:g}, evidence only): "
                             + "; ".join(f"{name} {100 * row.difference:+.1f} pp (95% CI "
                                         f"{100 * row.interval[0]:+.1f} to {100 * row.interval[1]:+.1f}; "
                                         f"{'non-inferior' if row.non_inferior else 'not shown'})"
                                         for name, row in harm.families.items()))
    per = after.per_scenario or {}
    if per:
        controls = (versus.per_scenario if versus is not None else None) or {}
        lines += ["", "| held-out scenario | episodes | failed: start | control | fine-tuned |", "|---|---|---|---|---|"]
        lines += [f"| {name} | {row['n']} | {row['before']} | {controls.get(name, '-')} | {row['after']} |"
                  for name, row in per.items()]
        lines.append("")
        rarely = [f"{name} ({row['before']} of {row['n']})" for name, row in per.items() if 2 * row["before"] < row["n"]]
        if rarely:
            lines.append("- the starting policy failed fewer than half of the held-out episodes of " + ", ".join(rarely)
                         + ": a kept failure is the failing scene at its own seed only, and at other seeds its entry "
                           "samples the failure's neighbourhood (the draws it does not narrow are listed under the "
                           "round's mining), where the starting policy mostly passes")
    return lines


def _recommendation(report: Mapping[str, Any]) -> Recommendation:
    """The report's recommendation (every loop report has one: a body without it is a :class:`LoopError`)."""
    return Recommendation.from_dict(report.get("recommendation"), source="the loop report (report.json)")


def _floor_lines(settings: Mapping[str, Any]) -> List[str]:
    """The report's loud line when the held-out minimums are below what can ever give evidence, or none."""
    note = evidence_floor_note(int(settings["min_heldout_episodes"]),
                               int(settings["min_heldout_families"]))
    return [f"**WARNING: {note}.**", ""] if note else []


def _heading_lines(report: Mapping[str, Any]) -> List[str]:
    """The report's title, where the loop started and ended, and its recommendation."""
    settings = report.get("settings", {})
    advice = _recommendation(report)
    return [
        "# dv2s loop", "",
        f"Started from `{settings.get('policy')}`; last fine-tuned policy `{report.get('policy')}`.", "",
        f"**{advice.sentence}**", "",
        f"Policy to use: `{advice.policy}`.", "",
    ]


def _settings_lines(settings: Mapping[str, Any]) -> List[str]:
    """The loop's settings in one paragraph (what each round does), and the loud line on too low minimums."""
    return [
        f"Per round: mining budget {settings.get('budget')} episodes ({settings.get('sampler')} sampler), at most "
        f"{'every' if settings.get('max_conversions') is None else settings.get('max_conversions')} cluster(s) converted, "
        f"{_replays_text(settings)}, "
        f"{settings.get('holdout_fraction')} of the mined families (parent scenarios) "
        f"held out, {settings.get('k_eval')} evaluation seeds per held-out scenario (at least "
        f"{settings['min_heldout_episodes']} held-out episodes from at least "
        f"{settings['min_heldout_families']} families for a drop or test), "
        f"{'a control arm fine-tuned without the mined scenarios, ' if settings.get('control') else 'no control arm, '}"
        f"fine-tuning ({settings['fine_tune_method']}) "
        f"{settings.get('fine_tune_steps')} steps (mined scenarios drawn with "
        f"probability {settings.get('mined_share')}, reward terms {_weights(settings.get('fine_tune_reward'))} "
        f"overriding the policy's own in training only), regression test on the starting bank with "
        f"{settings.get('regress_episodes')} seeds per scenario (margin {settings.get('margin')}).", "",
        *_floor_lines(settings),
    ]


def _dependence_line(after: HeldOutComparison) -> Optional[str]:
    """What the held-out drop's interval resampled, and that the paired McNemar tests count pairs of one family as
    independent when they are not; ``None`` without a drop or test."""
    interval = after.relative_drop_interval or [None, None]
    if after.relative_drop is None and after.mcnemar_p is None:
        return None
    parts = []
    if interval[0] is not None:
        unit = after.relative_drop_interval_unit or "scenario"
        count = after.relative_drop_interval_units
        what = "held-out families (the unit the split holds out)" if unit == "family" else "held-out scenarios"
        parts.append(f"the relative drop's 95 % interval [{interval[0]:.0%}, {interval[1]:.0%}] resamples whole "
                     + (f"{what}, {count} of them" if count is not None else what))
    if after.mcnemar_p is not None:
        per_family = after.pairs_per_family or {}
        largest = max(per_family.values()) if per_family else None
        parts.append("the McNemar tests pair episodes one by one, and pairs within one family (replays of one "
                     "failure, its conversion, their seeds) are not independent, so their p-values overstate the "
                     "evidence" + (f" (up to {largest} pairs from one family)" if largest and largest > 1 else ""))
    return f"- {'; '.join(parts)}" if parts else None


def _rounds_table_lines(report: Mapping[str, Any]) -> List[str]:
    """The table of the rounds, one line each, and the final policy against the starting one under it."""
    lines = [
        "| round | failures mined (against the policy) / episodes | clusters | kept | fine-tune / held-out scenarios "
        "| held-out failure rate start | control | fine-tuned | relative drop | two-sided McNemar p vs start | vs control "
        "| untouched failure rate start / control / fine-tuned | rest of the bank |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for record in _rounds(report):
        row = _round_row(record)
        lines.append(
            f"| {row['round']} | {row['failures']} ({row['against']}) / {row['episodes']} | {row['clusters']} | "
            f"{row['kept']} | {row['split']} | {row['before']} | {row['control']} | {row['after']} | {row['drop']} | "
            f"{row['p']} | {row['p_control']} | {row['untouched']} | {row['verdict']} |")
    final_line = _final_line(_report_final(report))
    if final_line:
        lines += ["", final_line]
    return lines


def _mining_lines(mine: Optional[MiningSummary], settings: Mapping[str, Any]) -> List[str]:
    """A round's mining step: what was found, converted and kept, and every reason a conversion was rejected (a
    JSON object of one is read as a :class:`~dv2s_gym.loop.record.MiningSummary`)."""
    if not recorded(mine):
        return []
    mine = MiningSummary.from_dict(mine)
    lines = [f"- mining ({mine.folder}): {mine.episodes} episodes, {mine.failures} "
             f"failures ({mine.failures_against_policy} avoidable by the reference driver), "
             f"{mine.clusters} clusters, conversions {mine.conversions}, "
             f"exact replays of other clusters {mine.replays or {}}, "
             f"{len(mine.replayed)} exact replay entries kept "
             f"in all, {mine.errors} episode errors"
             + (f"; **{mine.clusters_not_converted} clusters not converted** (at most "
                f"{settings.get('max_conversions')} per round)" if mine.clusters_not_converted
                else "")
             + (f"; **{mine.clusters_not_kept} clusters skipped**, neither converted nor replayed "
                f"(at most {settings.get('max_replays')} exact replays per round"
                + (f"; {mine.clusters_reference_failed} of them because the reference driver did not pass any of "
                   "their failing scenes, so they are neither replayed nor held out"
                   if mine.clusters_reference_failed else "") + ")"
                if mine.clusters_not_kept else "")]
    reasons = mine.rejected_reasons or ()
    for reason in reasons:  # every failed check of the conversion judge, each its own reason
        lines.append(f"  - rejected: {reason}")
    if (mine.rejected_reason_count or 0) > len(reasons):
        lines.append(f"  - and {mine.rejected_reason_count - len(reasons)} more rejection reasons "
                     f"(conversions.jsonl in {mine.folder})")
    for entry in mine.kept_entries:  # what an exact replay leaves as its parent draws it
        if entry.not_narrowed:
            lines.append(f"  - exact replay {entry.scenario} is the failing scene at its own seed only; at another "
                         "seed these keep the parent's draw: " + "; ".join(
                             f"{name} ({why})"
                             for name, why in sorted(entry.not_narrowed.items())))
    return lines


def _split_lines(split: Optional[SplitRecord]) -> List[str]:
    """A round's split of the mined scenarios into fine-tuning and held-out families."""
    if not recorded(split):
        return []
    return [f"- split by family ({split.groups} family groups): fine-tune families "
            f"{', '.join(split.fine_tune_family_names) or 'none'} "
            f"({', '.join(split.fine_tune_scenarios) or 'no scenario'}); held-out families "
            f"{', '.join(split.held_out_family_names) or 'none'} "
            f"({', '.join(split.held_out_scenarios) or 'no scenario'}; their parents are not fine-tuned on either)"]


def _fine_tuning_lines(steps: RoundSteps) -> List[str]:
    """A round's fine-tuning (by PPO or DAgger) and its control arm, one line each."""
    lines = []
    for key, tuned in (("fine_tune", steps.fine_tune), ("control", steps.control)):
        if not recorded(tuned):
            continue
        if key == "control":
            lines.append(f"- control arm: the same fine-tuning ({tuned.method}, {tuned.steps} "
                         f"steps, same seed) on {tuned.scenarios} scenarios, the "
                         f"{tuned.mined_left_out} mined scenario(s) left out: `{tuned.model}`")
            continue
        if tuned.method == FineTuneMethod.DAGGER:
            agreement = tuned.agreement or {}
            lines.append(f"- fine-tuned by DAgger ({tuned.steps} labelled steps, imitating "
                         f"`{tuned.reference}` on the policy's own states) on {tuned.scenarios} "
                         f"scenarios ({tuned.mined_upweighted} mined, upweighted); agreement with the "
                         f"reference on the {agreement.get('states')} labelled states "
                         f"{agreement.get('source')} -> {agreement.get('fine_tuned')}"
                         + "".join(f", resumed from iteration {r.get('from_iteration')}"
                                   + (f" (+{r['steps_into_next']} steps)" if r.get("steps_into_next") else "")
                                   for r in tuned.resumed or ())
                         + f": `{tuned.model}`")
        else:
            lines.append(f"- fine-tuned by PPO {tuned.steps} steps on {tuned.scenarios} scenarios "
                         f"({tuned.mined_upweighted} mined, upweighted), training reward weights "
                         f"{_weights((tuned.env_config or {}).get('reward_weights'))}: "
                         f"`{tuned.model}`")
    return lines


def _regression_lines(regress: Optional[RegressSummary]) -> List[str]:
    """A round's regression test on the starting bank, and the held-out families' parents in it."""
    if not recorded(regress):
        return []
    lines = [f"- regression test on the starting bank ({regress.episodes} paired episodes): "
             f"**{regress.verdict}** - {regress.reason}; failure rate new "
             f"{_summary_rate(regress.new_failure_rate)}, old "
             f"{_summary_rate(regress.old_failure_rate)}; report `{regress.report}`"]
    for name, row in (regress.held_out_parents or {}).items():
        lines.append(f"- held-out family's parent `{name}` (never fine-tuned on) in the regression test: "
                     f"failure rate new {_summary_rate(row['new'].get('failure_rate'))}, old "
                     f"{_summary_rate(row['old'].get('failure_rate'))}; stall rate new "
                     f"{_summary_rate(row['new'].get('stall_rate'))}, old "
                     f"{_summary_rate(row['old'].get('stall_rate'))}")
    return lines


def _round_lines(record: RoundRecord, settings: Mapping[str, Any]) -> List[str]:
    """A round's section: its policies and timings, then each step it ran, then where the next round starts."""
    steps = record.steps
    lines = ["", f"## Round {record.round}", "",
             f"- policy: `{record.policy}` -> fine-tuned policy `{record.new_policy or '-'}`",
             f"- timings: {_seconds(record.timings)}"]
    lines += _errored_lines(record)
    if steps.skipped:
        lines.append(f"- skipped: {steps.skipped}")
    lines += _mining_lines(steps.mine, settings)
    lines += _split_lines(steps.split)
    lines += _fine_tuning_lines(steps)
    lines += _reference_lines(steps.reference)
    lines += _heldout_lines(steps.after)
    lines += _untouched_lines(steps.untouched)
    lines += _regression_lines(steps.regress)
    if record.next_policy:
        lines.append(f"- the next round starts from `{record.next_policy}` ({record.next_policy_reason})")
    return lines


def render_markdown(report: Mapping[str, Any]) -> str:
    """The Markdown rendering of a loop report: heading and recommendation, settings, the rounds' table, and a
    section per round."""
    settings = report.get("settings", {})
    lines: List[str] = _heading_lines(report) + _settings_lines(settings) + _rounds_table_lines(report)
    for record in _rounds(report):
        lines += _round_lines(record, settings)
    return "\n".join(lines) + "\n"


_CSS = ("body{font-family:system-ui,sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:4px 8px;text-align:left}th{background:#f3f3f3}"
        ".PASS,.ACCEPTED{color:#186a1f;font-weight:bold}.FAIL,.REJECTED{color:#a11;font-weight:bold}"
        ".INCONCLUSIVE,.NOT_ACCEPTED{color:#a60}"
        "code{background:#f5f5f5;padding:1px 3px}.row{display:flex;flex-wrap:wrap;gap:8px}"
        "figure{margin:0}figcaption{font-size:small}")


def _markdown_to_html(lines: List[str]) -> str:
    """The few Markdown forms the round details use (headings, bullets, tables, bold) as HTML."""
    def inline(text: str) -> str:
        text = escape(text)
        text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
        return re.sub(r"`([^`]+)`", r"<code>\1</code>", text)

    html: List[str] = []
    table: List[List[str]] = []
    bullets: List[str] = []

    def flush() -> None:
        if bullets:
            html.append("<ul>" + "".join(f"<li>{b}</li>" for b in bullets) + "</ul>")
            bullets.clear()
        if table:
            head, *body = table
            html.append("<table><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head) + "</tr>"
                        + "".join("<tr>" + "".join(f"<td>{inline(c)}</td>" for c in row) + "</tr>" for row in body)
                        + "</table>")
            table.clear()

    for line in lines:
        if line.startswith("|"):
            if bullets:
                flush()
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(set(c) <= set("-") for c in cells):
                table.append(cells)
            continue
        if table:
            flush()
        if line.startswith("## "):
            flush()
            html.append(f"<h2>{inline(line[3:])}</h2>")
        elif line.startswith("- "):
            bullets.append(inline(line[2:]))
        elif line.startswith("  - ") and bullets:
            bullets[-1] += "<br>" + inline(line[4:])
        elif line.strip():
            flush()
            html.append(f"<p>{inline(line)}</p>")
    flush()
    return "".join(html)


def _clips_html(clips: Mapping[str, Any]) -> str:
    """Each kept mined scenario's videos (paths relative to the loop folder): a failure's clip beside the clip of
    its converted script (the videos of one ``group`` in one row)."""
    parts = []
    for scenario, videos in clips.items():
        if not videos:
            continue
        rows: List[List[Mapping[str, Any]]] = []
        for video in videos:
            if not video.get("path"):  # no clip: only the reason
                rows.append([video])
                continue
            if rows and video.get("group") is not None and rows[-1][0].get("group") == video.get("group"):
                rows[-1].append(video)
            else:
                rows.append([video])
        cells = "".join(
            "<div class=\"row\">" + "".join(
                f"<figure><video src=\"{escape(v['path'])}\" controls muted loop preload=\"metadata\" "
                f"width=\"320\"></video><figcaption>{escape(v['label'])}</figcaption></figure>" for v in row
                if v.get("path"))
            + "".join(f"<p class=\"note\">{escape(note)}</p>"
                      for note in dict.fromkeys(v.get("note") for v in row) if note)
            + "</div>" for row in rows)
        parts.append(f"<div class=\"clips\"><h3>{escape(scenario)}</h3>{cells}</div>")
    return "".join(parts)


def _rates_svg(title: str, bars: List[tuple]) -> str:
    """An inline SVG bar chart of failure rates with their 95 % intervals: ``bars`` = ``[(label, rate, low,
    high)]`` (``rate`` ``None``: no bar)."""
    bars = [b for b in bars if b[1] is not None]
    if not bars:
        return ""
    width, height, left, top = 120 * len(bars) + 60, 190, 40, 24
    plot = height - top - 36
    parts = [f'<svg width="{width}" height="{height}" role="img">'
             f'<title>{escape(title)}</title><text x="4" y="14" font-size="12">{escape(title)}</text>']
    for tick in (0.0, 0.5, 1.0):
        y = top + plot * (1 - tick)
        parts.append(f'<line x1="{left - 4}" x2="{width - 8}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>'
                     f'<text x="4" y="{y + 4:.1f}" font-size="10">{tick:.1f}</text>')
    for index, (label, rate, low, high) in enumerate(bars):
        x = left + 20 + index * 120
        y = top + plot * (1 - float(rate))
        parts.append(f'<rect x="{x}" y="{y:.1f}" width="60" height="{top + plot - y:.1f}" fill="#7a9cc6"/>')
        if low is not None and high is not None:
            y_low, y_high = top + plot * (1 - float(low)), top + plot * (1 - float(high))
            parts.append(f'<line x1="{x + 30}" x2="{x + 30}" y1="{y_low:.1f}" y2="{y_high:.1f}" stroke="#222"/>'
                         f'<line x1="{x + 22}" x2="{x + 38}" y1="{y_low:.1f}" y2="{y_low:.1f}" stroke="#222"/>'
                         f'<line x1="{x + 22}" x2="{x + 38}" y1="{y_high:.1f}" y2="{y_high:.1f}" stroke="#222"/>')
        parts.append(f'<text x="{x + 30}" y="{height - 18}" font-size="11" text-anchor="middle">{escape(label)}</text>'
                     f'<text x="{x + 30}" y="{height - 5}" font-size="10" text-anchor="middle">{float(rate):.2f}</text>')
    return "".join(parts) + "</svg>"


def _round_figures(record: RoundRecord) -> str:
    """The round's failure rates as charts: held-out (start, control, fine-tuned) and untouched."""
    steps = record.steps
    after = steps.after if steps.after is not None else HeldOutComparison()
    held = [(label, rate.rate, rate.low, rate.high) if rate is not None else (label, None, None, None)
            for label, rate in (("start", after.before), ("control", after.control), ("fine-tuned", after.after))]
    policies = (steps.untouched.policies if steps.untouched is not None else None) or {}
    untouched = [(label, ((policies.get(key) or {}).get("failure_rate") or {}).get("value"),
                  ((policies.get(key) or {}).get("failure_rate") or {}).get("low"),
                  ((policies.get(key) or {}).get("failure_rate") or {}).get("high"))
                 for label, key in (("start", "start"), ("control", "control"), ("fine-tuned", "fine_tuned"))]
    charts = [_rates_svg("held-out failure rate (95 % Wilson)", held),
              _rates_svg("untouched set failure rate (95 % Wilson)", untouched)]
    charts = [chart for chart in charts if chart]
    return f'<div class="row">{"".join(charts)}</div>' if charts else ""


def render_html(report: Mapping[str, Any], clips: Optional[Mapping[int, Mapping[str, Any]]] = None) -> str:
    """A self-contained HTML page (inline CSS, nothing fetched) of the loop report; ``clips``: round -> scenario ->
    ``[{"path", "label"}]`` videos shown per round (:func:`round_clips`)."""
    settings = report.get("settings", {})
    advice = _recommendation(report)
    rounds = _rounds(report)
    rows = []
    for record in rounds:
        row = _round_row(record)
        verdict = row["verdict"]
        cells = [row["round"], f"{row['failures']} / {row['episodes']}", row["clusters"], row["kept"], row["split"],
                 row["before"], row["control"], row["after"], row["drop"], row["p"], row["p_control"],
                 row["untouched"]]
        row = "".join(f"<td>{escape(str(c))}</td>" for c in cells)
        rows.append(f"<tr>{row}<td class=\"{escape(str(verdict))}\">{escape(str(verdict))}</td></tr>")
    final_line = _final_line(_report_final(report))
    final_html = f"<p>{escape(final_line).replace('**', '')}</p>" if final_line else ""
    head = ("<tr><th>round</th><th>failures / episodes mined</th><th>clusters</th><th>kept</th>"
            "<th>fine-tune / held-out</th><th>held-out failure rate: start</th><th>control</th><th>fine-tuned</th>"
            "<th>relative drop</th><th>two-sided McNemar p vs start</th><th>vs control</th>"
            "<th>untouched failure rate start / control / fine-tuned</th><th>rest of the bank</th></tr>")
    markdown = render_markdown(report).splitlines()
    details = []
    starts = [i for i, line in enumerate(markdown) if line.startswith("## Round ")]
    for position, begin in enumerate(starts):
        end = starts[position + 1] if position + 1 < len(starts) else len(markdown)
        number = rounds[position].round if position < len(rounds) else None
        details.append(_markdown_to_html(markdown[begin:end]))
        if position < len(rounds):
            details.append(_round_figures(rounds[position]))
        round_clips = (clips or {}).get(number) or {}
        if any(round_clips.values()):
            details.append("<h3>Clips of the kept mined scenarios: each failure beside its converted script driven "
                           "by the same policy (an entry without a clip says why)</h3>" + _clips_html(round_clips))
    return (f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>dv2s loop</title><style>{_CSS}</style>"
            f"</head><body><h1>dv2s loop</h1><p>Started from <code>{escape(str(settings.get('policy')))}</code>; "
            f"last fine-tuned policy <code>{escape(str(report.get('policy')))}</code>.</p>"
            f"<p class=\"{escape(advice.verdict.replace(' ', '_'))}\"><b>"
            f"{escape(advice.sentence)}</b></p><p>Policy to use: <code>"
            f"{escape(str(advice.policy))}</code></p><p>Mining budget {settings.get('budget')} "
            f"episodes per round, at most {escape(str('every' if settings.get('max_conversions') is None else settings.get('max_conversions')))} cluster(s) "
            f"converted, {escape(_replays_text(settings))}, "
            f"fine-tuning ({escape(str(settings['fine_tune_method']))}) "
            f"{settings.get('fine_tune_steps')} steps (reward terms "
            f"{escape(_weights(settings.get('fine_tune_reward')))} overridden in training only), "
            f"{'with' if settings.get('control') else 'without'} a control arm, {settings.get('k_eval')} "
            f"evaluation seeds per held-out scenario (Wilson 95 % intervals; the drop's interval resamples "
            f"held-out families, the unit the split holds out; the McNemar p-values pair episodes, and pairs within "
            f"a family are not independent; no drop or test below {settings['min_heldout_episodes']} held-out episodes or "
            f"{settings['min_heldout_families']} held-out families).</p>"
            + "".join(f"<p><strong>{escape(line.strip('*'))}</strong></p>" for line in _floor_lines(settings)[:1]) +
            f"<table>{head}{''.join(rows)}</table>{final_html}{''.join(details)}</body></html>\n")


def round_clips(report: Mapping[str, Any], out: Path) -> Dict[int, Dict[str, List[Dict[str, str]]]]:
    """Per round, each kept mined scenario's clips, as paths relative to ``out``: ``[{"path", "label", "group",
    "note"}]``, each failure's clip followed by the clip of its converted script driven by the policy (one
    reproduction episode, :data:`dv2s_gym.mining.conversion.convert.ENTRY_CONVERTED_VIDEO`), the two of one ``group`` shown
    side by side. The bank entry's own (its provenance ``video`` and ``converted_video``, and those of failures
    merged into it), else the mining run's (``failures/<cluster slug>/``). An exact replay shows only its failure
    clip, its ``note`` saying why (no converted script, or the judge's rejection of the script converted from it);
    a kept entry with no clip at all gets one item with ``path`` ``None`` whose ``note`` says why (an extra exact
    replay of a cluster no conversion tried is not filmed)."""
    settings = report.get("settings") or {}
    bank = Path(settings.get("bank_dir") or Path(out) / "bank")
    found: Dict[int, Dict[str, List[Dict[str, str]]]] = {}
    for record in _rounds(report):
        mine = record.steps.mine if record.steps.mine is not None else MiningSummary()
        policy = record.policy or report.get("policy")
        split = record.steps.split if record.steps.split is not None else SplitRecord()
        held = set(split.held_out_scenarios)
        clips: Dict[str, List[Dict[str, str]]] = {}
        for entry in mine.kept_entries:
            scenario = str(entry.scenario)
            videos = clips.setdefault(f"{scenario} ({'held out' if scenario in held else 'fine-tuned on'})", [])
            for video, label, group, note in _entry_clips(entry, bank / scenario, mine, policy):
                path = os.path.relpath(video.resolve(), Path(out).resolve())
                if all(v["path"] != path for v in videos):
                    videos.append({"path": path, "label": label, "group": f"{scenario}/{group}",
                                   **({"note": note} if note else {})})
            if not videos:
                videos.append({"path": None, "label": "no clip", "group": f"{scenario}/none",
                               "note": _no_clip_reason(entry, bank / scenario, mine)})
        found[int(record.round or 0)] = clips
    return found


def _short_reason(reason: Any, limit: int = 160) -> str:
    """A judge's rejection in short: its stage and what failed, without the listed values (``"parameters: the new
    scenario's ranges do not contain the failing values"``), cut at ``limit`` characters."""
    parts = str(reason).split(": ")
    text = ": ".join(parts[:2])
    return text if len(text) <= limit else text[:limit - 1].rstrip() + "\u2026"


def _rejection_note(rejections: Any) -> Optional[str]:
    """The note of an exact replay kept after the script converted from its failure was rejected; ``None`` when no
    rejection is recorded."""
    if not isinstance(rejections, list) or not rejections:
        return None
    return (f"a script was converted from this failure and rejected ({_short_reason(rejections[0])}): the bank "
            "keeps the exact replay of the failing scene, so only the failure clip is shown")


def _conversion_record(mine: MiningSummary, cluster: Any) -> Dict[str, Any]:
    """The mining run's conversion record of ``cluster`` (its ``failures/<slug>/conversion/report.json``, the
    conversion's file as written); ``{}`` when there is none."""
    if not mine.folder or cluster is None:
        return {}
    try:
        record = json.loads((Path(mine.folder) / "failures" / cluster_slug(cluster, None) / CONVERSION_DIR
                             / "report.json").read_text())
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def _no_clip_reason(entry: MinedEntry, folder: Path, mine: MiningSummary) -> str:
    """Why a kept mined scenario shows no clip in the loop report."""
    source = _entry_source(folder) if folder.is_dir() else {}
    rejected = _rejection_note(source.get("converted_rejections")
                               or _conversion_record(mine, entry.cluster).get("rejections"))
    if rejected:
        return ("no clip: " + rejected.split(": the bank keeps", 1)[0] + "; no clip of the failure was found")
    if entry.replay or source.get("replay"):
        return ("an extra exact replay of a cluster no conversion tried: no clip recorded (only the failures sent "
                "to conversion are filmed; the entry keeps the failing episode's trace)")
    if not folder.is_dir():
        return "no clip: the bank entry is gone and the mining run has no clip of its failure"
    return "no clip recorded for this entry (neither the bank entry nor the mining run has one)"


def _entry_source(folder: Path) -> Dict[str, Any]:
    """The provenance (``source``) of the bank entry in ``folder``; ``{}`` when it cannot be read."""
    try:
        meta = read_json(folder, SIDECAR)
    except Exception:  # the clips are extra: without the sidecar, the files alone
        return {}
    source = meta.get("source") if isinstance(meta, Mapping) else None
    return dict(source) if isinstance(source, Mapping) else {}


def _own_file(folder: Path, named: Any, default: str) -> Path:
    """The entry's own file a provenance value names (a relative path inside the entry folder), else
    ``default``'s."""
    relative = str(named) if isinstance(named, str) and named else default
    if Path(relative).is_absolute() or ".." in Path(relative).parts:
        relative = default
    return folder / relative


def _entry_clips(entry: MinedEntry, folder: Path, mine: MiningSummary, policy: Optional[str]) -> List[tuple]:
    """``[(video, label, group, note)]`` of one kept mined scenario (:func:`round_clips`); ``policy``: the round's,
    named in a caption when the clip's own record does not name it (JSON objects of the entry and the mining step
    are read as their records)."""
    entry, mine = MinedEntry.from_dict(entry), MiningSummary.from_dict(mine)
    scenario, cluster = str(entry.scenario), entry.cluster
    replay_note = ("an exact replay of the failing scene: it has no converted script, so only the failure clip "
                   "is shown")
    found: List[tuple] = []
    if folder.is_dir():
        source = _entry_source(folder)
        replay = bool(entry.replay or source.get("replay"))
        records = [("", source)] + [(f"merged/{n}/", merged) for n, merged in
                                    enumerate(source.get("merged") or [], start=1) if isinstance(merged, Mapping)]
        for prefix, provenance in records:
            failure = _own_file(folder, provenance.get("video"), prefix + ENTRY_VIDEO)
            converted = _own_file(folder, provenance.get("converted_video"), prefix + ENTRY_CONVERTED_VIDEO)
            label = (f"failure of cluster {provenance.get('cluster') or cluster}" if not prefix
                     else f"failure merged into it ({prefix.rstrip('/')})")
            if provenance.get("parent") and provenance.get("seed") is not None:
                label += f" ({provenance['parent']}, seed {provenance['seed']})"
            note = (_rejection_note(provenance.get("converted_rejections")) or replay_note) if replay else None
            if not replay and not converted.is_file():
                clip = (provenance.get("reproduction") or {}).get("clip") or {}
                note = (f"no clip of the converted script ({clip['error']})" if clip.get("error")
                        else "no clip of the converted script was recorded")
            if failure.is_file():
                found.append((failure, label, prefix, note))
            if not replay and converted.is_file():
                found.append((converted, clip_caption(scenario, provenance, merged=bool(prefix)), prefix, None))
        if found:
            return found
    if mine.folder:  # the bank entry is gone: the mining run's copy
        run = Path(mine.folder) / "failures" / cluster_slug(cluster, None)
        run_note = ((_rejection_note(_conversion_record(mine, cluster).get("rejections")) or replay_note)
                    if entry.replay else None)
        for video in sorted(run.glob("*.webm")) if run.is_dir() else []:
            found.append((video, f"failure of cluster {cluster} (mining run)", "run", run_note))
        converted = run / CONVERSION_DIR / ENTRY_CONVERTED_VIDEO
        if found and not entry.replay and converted.is_file():
            try:
                conversion = json.loads((run / CONVERSION_DIR / "report.json").read_text())
            except (OSError, ValueError):
                conversion = {}
            caption = clip_caption(scenario, {**conversion, "policy": conversion.get("policy") or policy},
                                   merged=conversion.get("status") == ConversionStatus.MERGED)
            found.append((converted, caption + " (mining run)", "run", None))
    return found


def write_loop_reports(report: Mapping[str, Any], out: Path) -> Dict[str, Path]:
    """Write ``report.json``, ``report.md`` (and ``report.html`` when available) atomically; returns their paths.

    With two or more regression-tested rounds, ``final_vs_start`` (:func:`final_vs_start`) is added to them, and to
    each accepted round the same check over the rounds up to it (:func:`with_cross_round_checks`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    report = with_cross_round_checks(report, out)
    report["recommendation"] = recommendation(report).to_dict()
    paths = {"json": atomic_write_json(out / "report.json", dict(report), indent=1) or out / "report.json"}
    markdown = render_markdown(report)
    atomic_write_text(out / "report.md", markdown)
    paths["md"] = out / "report.md"
    try:
        clips = round_clips(report, out)
    except OSError:  # the clips are extra: a report without them beats no report
        clips = {}
    atomic_write_text(out / "report.html", render_html(report, clips))
    paths["html"] = out / "report.html"
    return {key: Path(value) for key, value in paths.items()}
