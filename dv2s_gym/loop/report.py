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

This module holds the report's cross-round checks (:func:`final_vs_start`), the clips of the kept mined
scenarios (:func:`round_clips`) and the writing of the three files (:func:`write_loop_reports`); the sentences
and the Markdown form are :mod:`dv2s_gym.loop.report_text`, the page :mod:`dv2s_gym.loop.html`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

from dv2s_gym.loop.html import render_html
from dv2s_gym.loop.record import FinalVsStart, LoopReportBody, MinedEntry, MiningSummary, SplitRecord
from dv2s_gym.loop.report_text import (errored_note, errored_text, rate_text, reference_gate_text, render_markdown,
                                       report_rounds, round_summary)
from dv2s_gym.loop.verdict import ACCEPTED, judge_round, recommendation
from dv2s_gym.mining.conversion.files import CONVERSION_DIR, ENTRY_CONVERTED_VIDEO, ENTRY_VIDEO, cluster_slug
from dv2s_gym.mining.conversion.record import ConversionOutcome, read_conversion_outcome
from dv2s_gym.mining.report_text import clip_caption
from dv2s_gym.regress.records import BankInfo, PairedComparison, PairedEpisode, Summary
from dv2s_gym.regress.report import build_report, load_report, write_json
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.entries import SIDECAR, read_json

__all__ = [
    "write_loop_reports",
    "round_clips",
    "final_vs_start",
    "with_cross_round_checks",
    "FINAL_VS_START_DIR",
    "rate_text",
    "render_markdown",
    "round_summary",
    "errored_note",
    "errored_text",
    "reference_gate_text",
    "render_html",
]


FINAL_VS_START_DIR = "final_vs_start"
"""Folder (in the loop folder) of the final-vs-starting-policy paired regression report."""


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


def final_vs_start(report: LoopReportBody, out: Optional[Path] = None,
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
    tested = [r for r in report_rounds(report) if r.steps.regress is not None and r.steps.regress.report]
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


def with_cross_round_checks(report: LoopReportBody, out: Optional[Path] = None,
                            folder: Optional[Path] = None) -> LoopReportBody:
    """``report`` with the cross-round check (:func:`final_vs_start` over the rounds up to it) recorded in each
    round that its own tests accepted (``None`` before two rounds were regression-tested), and, with two or more
    tested rounds, the report's own ``final_vs_start`` (its paired report written under ``out``). A policy the
    check rejected is never the policy to use (:func:`dv2s_gym.loop.verdict.recommendation`)."""
    rounds = report_rounds(report)
    for index, record in enumerate(rounds):
        judged = judge_round(record)
        if judged is not None and judged.verdict == ACCEPTED and not record.cross_round_checked:
            checked = final_vs_start(LoopReportBody(rounds=tuple(rounds[:index + 1])), folder=folder or out)
            rounds[index] = record.with_cross_round_check(checked)
    body = report.replace(rounds=tuple(rounds))
    if not body.cross_round_checked:
        final = final_vs_start(body, out, folder)
        if final is not None:
            body = body.replace(final_vs_start=final)
    return body


def round_clips(report: LoopReportBody, out: Path) -> Dict[int, Dict[str, List[Dict[str, str]]]]:
    """Per round, each kept mined scenario's clips, as paths relative to ``out``: ``[{"path", "label", "group",
    "note"}]``, each failure's clip followed by the clip of its converted script driven by the policy (one
    reproduction episode, :data:`dv2s_gym.mining.conversion.convert.ENTRY_CONVERTED_VIDEO`), the two of one ``group`` shown
    side by side. The bank entry's own (its provenance ``video`` and ``converted_video``, and those of failures
    merged into it), else the mining run's (``failures/<cluster slug>/``). An exact replay shows only its failure
    clip, its ``note`` saying why (no converted script, or the judge's rejection of the script converted from it);
    a kept entry with no clip at all gets one item with ``path`` ``None`` whose ``note`` says why (an extra exact
    replay of a cluster no conversion tried is not filmed)."""
    settings = report.settings
    bank = Path((settings.bank_dir if settings is not None else None) or Path(out) / "bank")
    found: Dict[int, Dict[str, List[Dict[str, str]]]] = {}
    for record in report_rounds(report):
        mine = record.steps.mine if record.steps.mine is not None else MiningSummary()
        policy = record.policy or report.policy
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


def _conversion_outcome(mine: MiningSummary, cluster: Any) -> Optional[ConversionOutcome]:
    """The mining run's conversion report of ``cluster`` (its ``failures/<slug>/conversion/report.json``, the
    conversion's file as written); ``None`` when there is none or it cannot be read (the clips are extra)."""
    if not mine.folder or cluster is None:
        return None
    try:
        return read_conversion_outcome(Path(mine.folder) / "failures" / cluster_slug(cluster, None) / CONVERSION_DIR
                                       / "report.json")
    except (OSError, ValueError):  # RecordError is a ValueError
        return None


def _conversion_rejections(mine: MiningSummary, cluster: Any) -> Optional[List[str]]:
    """Every failed check of the conversion of ``cluster`` (:func:`_conversion_outcome`); ``None`` without one."""
    outcome = _conversion_outcome(mine, cluster)
    return list(outcome.rejections) if outcome is not None and outcome.rejections is not None else None


def _no_clip_reason(entry: MinedEntry, folder: Path, mine: MiningSummary) -> str:
    """Why a kept mined scenario shows no clip in the loop report."""
    source = _entry_source(folder) if folder.is_dir() else {}
    rejected = _rejection_note(source.get("converted_rejections")
                               or _conversion_rejections(mine, entry.cluster))
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
        run_note = ((_rejection_note(_conversion_rejections(mine, cluster)) or replay_note)
                    if entry.replay else None)
        for video in sorted(run.glob("*.webm")) if run.is_dir() else []:
            found.append((video, f"failure of cluster {cluster} (mining run)", "run", run_note))
        converted = run / CONVERSION_DIR / ENTRY_CONVERTED_VIDEO
        if found and not entry.replay and converted.is_file():
            conversion = _conversion_outcome(mine, cluster) or ConversionOutcome()
            # the caption reads the reproduction's clip and the policy, as it reads an entry's provenance
            caption = clip_caption(scenario, {"reproduction": conversion.reproduction,
                                              "policy": conversion.policy or policy}, merged=conversion.merged)
            found.append((converted, caption + " (mining run)", "run", None))
    return found


def write_loop_reports(report: LoopReportBody, out: Path) -> Dict[str, Path]:
    """Write ``report.json`` (the body ``report``), ``report.md`` (and ``report.html`` when available) atomically;
    returns their paths.

    With two or more regression-tested rounds, ``final_vs_start`` (:func:`final_vs_start`) is added to them, and to
    each accepted round the same check over the rounds up to it (:func:`with_cross_round_checks`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    report = with_cross_round_checks(report, out)
    report = report.replace(recommendation=recommendation(report).to_dict())
    paths = {"json": atomic_write_json(out / "report.json", report.to_dict(), indent=1) or out / "report.json"}
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
