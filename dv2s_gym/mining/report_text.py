"""Sentences of the mining report shared by its Markdown, summary and HTML forms (no Scenic, no highway-env)."""

from __future__ import annotations

import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from dv2s_gym.mining.report_record import MineCounts
from scenario_bank.failure_types import severity_order, type_label
from scenario_bank.records import Failure
from scenario_bank.named_registry import replaced_text

__all__ = ["replaced_text", "replaced_in", "breadth", "rate_text", "number_text", "percent_text", "seed_text", "error_warning",
           "NOT_COMPARED_REASONS", "not_compared_reason", "not_compared_counts", "not_compared_text",
           "not_compared_names_text", "parameter_check_text", "clip_caption", "by_type_text"]

NOT_COMPARED_REASONS: Tuple[Tuple[str, Tuple[str, ...], str], ...] = (
    ("no_counterpart", ("defines no numeric parameter of that name", "sets the same quantity of that object"),
     "with no counterpart in the new script"),
    ("actor_missing", ("its object has no counterpart",), "whose actor has no counterpart in the new script"),
    ("not_interval", ("cannot read as an interval",),
     "whose counterpart's distribution is not an interval the judge can read"),
    ("reaches_no_object", ("reaches no object",), "named alike in the new script, where it reaches no object"),
    ("feeds_no_object", ("feeds no object of its script",), "feeding no object of the parent script"),
    ("other_meaning", ("named alike but not the same meaning",),
     "named alike in the new script, where it means something else"),
    ("together", ("only together with other parameters",),
     "setting their object's quantities only together with other parameters"),
    ("ambiguous", ("ambiguous:",), "with more than one possible counterpart"),
    ("two_actors", ("one actor cannot be two",), "whose counterpart's actor would stand for two of the parent's"),
    ("unread_quantity", ("the quantity it sets cannot be compared",),
     "setting a quantity the judge cannot compare between the two scripts (an expression it cannot read in one)"),
    ("other", (), "for another reason"),
)
"""``(key, phrases of the conversion judge's reasons, words)`` of each reason a failing parameter was not compared
with the new script (:func:`dv2s_gym.mining.conversion.parameters.compare_parameters`' ``not_comparable``), in the order
the reports list them."""


def not_compared_reason(why: Any) -> str:
    """The key of :data:`NOT_COMPARED_REASONS` a judge's reason for not comparing a parameter falls under."""
    text = str(why)
    for key, phrases, _ in NOT_COMPARED_REASONS:
        if any(phrase in text for phrase in phrases):
            return key
    return "other"


def not_compared_counts(not_compared: Optional[Mapping[str, Any]]) -> Dict[str, int]:
    """``{reason key: n}`` of a conversion's ``not_comparable`` (``{name: why}``), in :data:`NOT_COMPARED_REASONS`'
    order."""
    found: Dict[str, int] = {}
    for why in (not_compared or {}).values():
        key = not_compared_reason(why)
        found[key] = found.get(key, 0) + 1
    return {key: found[key] for key, _, _ in NOT_COMPARED_REASONS if key in found}


def not_compared_text(counts: Mapping[str, int]) -> str:
    """``"2 with no counterpart in the new script, 1 whose counterpart's distribution is not an interval the judge
    can read"``: :func:`not_compared_counts` in words, each reason with its count."""
    words = {key: text for key, _, text in NOT_COMPARED_REASONS}
    return ", ".join(f"{n} {words.get(key, key)}" for key, n in counts.items() if n)


def not_compared_names_text(not_compared: Mapping[str, Any]) -> str:
    """``"kerb_offset, speed_after_cut_in with no counterpart in the new script; cut_in_gap whose ..."``: the
    parameters of one conversion that were not compared, grouped by reason."""
    groups: Dict[str, List[str]] = {}
    for name in sorted(not_compared):
        groups.setdefault(not_compared_reason(not_compared[name]), []).append(str(name))
    return "; ".join(f"{', '.join(groups[key])} {text}" for key, _, text in NOT_COMPARED_REASONS if key in groups)


def number_text(value: Any, digits: int = 1) -> str:
    """A finite number with ``digits`` decimals, else ``-``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        return "-"
    return f"{value:.{digits}f}"


def percent_text(entry: Optional[Mapping[str, Any]]) -> str:
    """A rate with its interval in percent (``{"value", "low", "high"}``), else ``-``."""
    if not entry or entry.get("value") is None:
        return "-"
    return f"{100 * entry['value']:.1f}% [{100 * entry['low']:.1f}, {100 * entry['high']:.1f}]"


def replaced_in(settings: Mapping[str, Any]) -> List[str]:
    """The built-in entries plug-ins replaced for a run (``settings``: its ``settings.json``, whose
    ``code_identity`` lists them; :func:`scenario_bank.named_registry.replaced_built_ins`)."""
    identity = settings.get("code_identity")
    return list(identity.get("replaced built-ins") or []) if isinstance(identity, Mapping) else []


def seed_text(settings: Mapping[str, Any]) -> str:
    """The run's seed, and where it came from when another command derived it (``settings["origin"]``).

    ``dv2s loop`` mines round ``R`` of a loop with seed ``S`` with the seed ``1000 * S + R``; the report names
    the loop's own seed and round beside it, so a loop run with seed 0 is not read as one with seed 1.
    """
    text = f"seed {settings.get('seed')}"
    origin = settings.get("origin")
    if isinstance(origin, Mapping) and origin:
        parts = [str(origin.get("command") or "another command")]
        if origin.get("seed") is not None:
            parts.append(f"seed {origin['seed']}")
        if origin.get("round") is not None:
            parts.append(f"round {origin['round']}")
        text += f" (derived by {parts[0]}" + (f" from its {', '.join(parts[1:])}" if parts[1:] else "") + ")"
    return text


def by_type_text(by_type: Mapping[str, int]) -> str:
    """``"collision 5, off road 1, stall 1"``: failures per type, most severe first, each type called by its row's
    label in the failure table (:func:`~scenario_bank.failure_types.type_label`); ``"none"`` for no failure."""
    return ", ".join(f"{type_label(name)} {by_type[name]}" for name in severity_order(by_type)) or "none"


def breadth(counts: MineCounts) -> str:
    """How broad the failures found are: failures, distinct behaviours, (scenario, failure type) pairs, scenarios
    with a failure, the failures per type (:func:`by_type_text`), and collisions and stalls apart (zero included)."""
    apart = "" if counts.collisions is None or counts.stalls is None else \
        f"; collisions {counts.collisions}, stalls {counts.stalls}"
    return (f"{counts.failures} failure(s): {counts.behaviours} distinct behaviour(s), "
            f"{counts.scenario_failure_types} (scenario family, failure type) pair(s), "
            f"{counts.scenarios_failing} scenario famil(ies) with a failure; by type: "
            f"{by_type_text(counts.failures_by_type or {})}{apart}")


def rate_text(rate: Optional[Mapping[str, Any]]) -> str:
    """The estimated failure rate under the scenarios' own parameter distributions, as one sentence."""
    if not rate or not rate.get("available"):
        reason = (rate or {}).get("reason") or "no episodes"
        return f"Failure rate under the scenarios' own parameter distributions: not estimated ({reason})."
    overall = rate.get("overall") or {}
    errored = rate.get("errored") or {}
    empty = [name for name, estimate in (rate.get("scenarios") or {}).items() if not (estimate or {}).get("n")]
    unsampled = [name for name in empty if not errored.get(name)]
    broken = [name for name in empty if errored.get(name)]
    return ("Failure rate under the scenarios' own parameter distributions (importance-weighted, each scenario "
            f"equally likely): {percent_text(overall)} from {overall.get('n', 0)} episodes, as precise as "
            f"{number_text(overall.get('ess'))} draws of those distributions would be."
            + (f" {len(unsampled)} of {len(rate.get('scenarios') or {})} scenarios were never drawn: the figure "
               "speaks for them only as far as the drawn ones stand for the rest; a larger --budget covers them."
               if unsampled else "")
            + (f" {len(broken)} of {len(rate.get('scenarios') or {})} scenarios were drawn "
               f"({sum(errored[name] for name in broken)} episode(s)) but every episode of them ended in an error: "
               "the figure says nothing about them; see the errors." if broken else "")
            + (" The sampler almost stopped drawing some regions, so failures there are missing from the estimate: "
               "it can be far too low; a random-sampler run estimates it without that risk." if rate.get("collapsed")
               else ""))


def error_warning(errors: int, episodes: int, first: str) -> str:
    """The loud line for a run with ``errors`` of its ``episodes`` ended in an error (``first``: one's message)."""
    what = (f"all {episodes} episodes ended in an error: the run measured nothing" if errors == episodes else
            f"{errors} of {episodes} episodes ended in an error and count in no failure figure")
    return (f"WARNING: {what} (e.g. {first}); the report's Errors section lists them: fix what they name (the "
            "policy, the scenario or a plug-in) and rerun")


def parameter_check_text(counts: MineCounts) -> str:
    """``"Parameter check of the conversions: 3 failing parameter value(s) compared with the new scripts' ranges, 3
    not compared: 2 with no counterpart in the new script, 1 ..."``, from a mining report's ``counts`` (as
    :func:`dv2s_gym.mining.report.build_report` makes them)."""
    text = (f"Parameter check of the conversions: {counts.parameters_compared} failing parameter value(s) "
            f"compared with the new scripts' ranges, {counts.parameters_not_compared} not compared")
    reasons = not_compared_text(counts.parameters_not_compared_by_reason)
    return text + (f": {reasons}" if reasons else "")


def clip_caption(scenario: str, source: Mapping[str, Any], *, merged: bool = False) -> str:
    """The caption of a converted script's clip from its provenance (or conversion record): the scenario, the
    policy, the seed, and whether the episode failed and how. ``merged``: the clip is of the script converted from
    a failure merged into the bank entry ``scenario`` (the bank kept the entry's own script, not this one)."""
    clip = (source.get("reproduction") or {}).get("clip") or {}
    policy = source.get("policy")
    what = (f"the script converted from a failure merged into {scenario} (a copy or near-copy of its script; the "
            f"bank keeps the entry's own script, not this one)" if merged
            else f"generated scenario {scenario} (the converted script)")
    text = f"{what} driven by {policy or 'the policy'}"
    if clip.get("seed") is not None:
        text += f", seed {clip['seed']}"
    failure = Failure.of(clip.get("failure"))
    if not clip:
        return text
    if not clip.get("failed"):
        return text + ": it did not fail"
    how = failure.type if failure is not None else "failed"
    if failure is not None and failure.collision_type:
        how += f" ({failure.collision_type})"
    if failure is not None and failure.with_kind:
        how += f" with a {failure.with_kind}"
    same = "the same way as the source failure" if clip.get("reproduced") else "another way than the source failure"
    return text + f": it failed, {how}, {same}"
