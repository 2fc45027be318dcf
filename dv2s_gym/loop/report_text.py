"""The loop report in words: the sentences it shares with the loop's log (rates, errored episodes, the reference gate,
a round's summary) and its Markdown form (:func:`render_markdown`), read from the body of ``report.json``; the
report's contents are described in :mod:`dv2s_gym.loop.report`."""

from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional

from dv2s_gym.loop.errored import merged_messages, messages_text
from dv2s_gym.loop.record import (ControlTable, ErroredEpisodes, FinalVsStart, HeldOutComparison, LoopReportBody,
                                  MiningSummary, PairedTable, ReferenceGate, RegressSummary, RoundRecord, RoundSteps,
                                  SplitRecord, UntouchedComparison, recorded)
from dv2s_gym.loop.verdict import HELDOUT_ALPHA, Recommendation, evidence_floor_note
from dv2s_gym.mining.report_text import by_type_text
from policies.card_record import FineTuneMethod
from policies.stats import Rate

__all__ = [
    "rate_text",
    "report_rounds",
    "errored_text",
    "errored_note",
    "errored_by_stage",
    "round_summary",
    "reference_gate_text",
    "render_markdown",
]


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


_ORDER = ("mine", "split", "reference", "before", "fine_tune", "control", "after", "untouched", "regress")


def _seconds(timings: Mapping[str, Any]) -> str:
    steps = sorted(timings, key=lambda s: _ORDER.index(s) if s in _ORDER else len(_ORDER))
    return ", ".join(f"{step} {float(timings[step]):.0f} s" for step in steps) or "-"


def report_rounds(report: LoopReportBody) -> List[RoundRecord]:
    """The rounds of a loop report's body (``report.json``'s ``rounds``)."""
    return list(report.round_records)


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


def _recommendation(report: LoopReportBody) -> Recommendation:
    """The report's recommendation (every loop report has one: a body without it is a :class:`LoopError`)."""
    return Recommendation.from_dict(report.recommendation, source="the loop report (report.json)")


def _floor_lines(settings: Mapping[str, Any]) -> List[str]:
    """The report's loud line when the held-out minimums are below what can ever give evidence, or none."""
    note = evidence_floor_note(int(settings["min_heldout_episodes"]),
                               int(settings["min_heldout_families"]))
    return [f"**WARNING: {note}.**", ""] if note else []


def _heading_lines(report: LoopReportBody) -> List[str]:
    """The report's title, where the loop started and ended, and its recommendation."""
    advice = _recommendation(report)
    return [
        "# dv2s loop", "",
        f"Started from `{report.start_policy}`; last fine-tuned policy `{report.policy}`.", "",
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


def _rounds_table_lines(report: LoopReportBody) -> List[str]:
    """The table of the rounds, one line each, and the final policy against the starting one under it."""
    lines = [
        "| round | failures mined (against the policy) / episodes | clusters | kept | fine-tune / held-out scenarios "
        "| held-out failure rate start | control | fine-tuned | relative drop | two-sided McNemar p vs start | vs control "
        "| untouched failure rate start / control / fine-tuned | rest of the bank |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for record in report_rounds(report):
        row = _round_row(record)
        lines.append(
            f"| {row['round']} | {row['failures']} ({row['against']}) / {row['episodes']} | {row['clusters']} | "
            f"{row['kept']} | {row['split']} | {row['before']} | {row['control']} | {row['after']} | {row['drop']} | "
            f"{row['p']} | {row['p_control']} | {row['untouched']} | {row['verdict']} |")
    final_line = _final_line(report.final_vs_start)
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


def render_markdown(report: LoopReportBody) -> str:
    """The Markdown rendering of a loop report's body: heading and recommendation, settings, the rounds' table,
    and a section per round."""
    settings = report.settings.to_dict() if report.settings is not None else {}  # read by name
    lines: List[str] = _heading_lines(report) + _settings_lines(settings) + _rounds_table_lines(report)
    for record in report_rounds(report):
        lines += _round_lines(record, settings)
    return "\n".join(lines) + "\n"
