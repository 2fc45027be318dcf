"""The episodes of a loop step that errored, and their error messages counted per scenario.

An errored episode (a scene the scenario's sampler could not produce, a crashed or hung worker...) counts in no rate
and no test; the loop records them per step (:func:`errored_episodes`), says so in its log and lists them in its
reports, each scenario with its distinct error messages and how many episodes ended in each.
"""

from __future__ import annotations

import re
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

from dv2s_gym.loop.record import ErroredEpisodes
from scenario_bank.records import EpisodeRecord, HeldOutEpisode, RegressEpisode

__all__ = ["ERROR_MESSAGES_KEPT", "EpisodeRecords", "error_message", "message_kind", "errored_episodes", "merged_messages",
           "messages_text"]

ERROR_MESSAGES_KEPT = 5
"""How many distinct error messages a report lists per scenario (the most frequent, with counts; the rest are
counted). The record keeps them all, so the steps of a round add up exactly (:func:`merged_messages`)."""

_SEED = re.compile(r"\bseed (-?\d+)\b")
SEED_MARK = "seed <seed>"
"""What stands for an episode's seed in a message's kind (:func:`message_kind`)."""


def error_message(error: Any) -> str:
    """An episode's error as the loop records it: its first line, cut to 300 characters (``"error"`` when empty)."""
    text = str(error).strip()
    return text.splitlines()[0][:300] if text else "error"


def message_kind(message: str) -> str:
    """The kind of an error message: the message with each seed it names (``seed 17``) replaced by
    :data:`SEED_MARK`, so that the same trouble on different seeds (a worker that hung on each of them) counts as
    one message."""
    return _SEED.sub(SEED_MARK, str(message))


EpisodeRecords = Sequence[Union[EpisodeRecord, HeldOutEpisode, RegressEpisode]]
"""Episode records: of a mining run (``episodes.jsonl``), a held-out evaluation (``heldout.jsonl``) or a regression
run (a report's results)."""


def errored_episodes(records: EpisodeRecords) -> ErroredEpisodes:
    """The episodes of ``records`` (:data:`EpisodeRecords`) that errored (an ``error`` set: a scene that could not be sampled, a crashed or
    hung worker...), which no rate counts, as an :class:`~dv2s_gym.loop.record.ErroredEpisodes` (its JSON
    object: ``{"episodes": n, "scenarios": {scenario: n}, "messages": {scenario: [{"message", "count"[,
    "example"]}]}, "examples": {scenario: its first error}}``). ``messages`` holds every
    distinct kind of error of each scenario (:func:`message_kind` of :func:`error_message`: the seed out of it) with
    how many episodes ended in it and, when the kind differs from the message, the first message of that kind as its
    ``example``; the most frequent first (ties in the order they came); :func:`messages_text` lists the
    :data:`ERROR_MESSAGES_KEPT` most frequent and counts the rest."""
    scenarios: Dict[str, int] = {}
    counts: Dict[str, Dict[str, int]] = {}
    examples: Dict[str, Dict[str, str]] = {}
    firsts: Dict[str, str] = {}
    for record in records:
        if not record.error:
            continue
        name, error = str(record.scenario), record.error
        scenarios[name] = scenarios.get(name, 0) + 1
        found = counts.setdefault(name, {})
        message = error_message(error)
        firsts.setdefault(name, message)
        kind = message_kind(message)
        found[kind] = found.get(kind, 0) + 1
        if kind != message:
            examples.setdefault(name, {}).setdefault(kind, message)
    return ErroredEpisodes(episodes=sum(scenarios.values()), scenarios=dict(sorted(scenarios.items())),
                           messages=_ranked(counts, examples), examples={name: firsts[name] for name in sorted(firsts)})


def _ranked(counts: Mapping[str, Mapping[str, int]],
            examples: Optional[Mapping[str, Mapping[str, str]]] = None) -> Dict[str, List[Dict[str, Any]]]:
    """``{scenario: [{"message", "count"[, "example"]}]}`` from ``{scenario: {message: count}}`` (and the
    ``{scenario: {message: example}}`` of the kinds that have one), every message, the most frequent first (ties
    keep the order they came in)."""
    examples = examples or {}
    return {name: [{"message": text, "count": n,
                    **({"example": examples[name][text]} if text in examples.get(name, {}) else {})}
                   for text, n in sorted(counts[name].items(), key=lambda item: -item[1])]
            for name in sorted(counts)}


def merged_messages(found: Sequence[ErroredEpisodes]) -> Dict[str, List[Dict[str, Any]]]:
    """The ``messages`` of several :func:`errored_episodes` (steps, policies) added up per scenario: ``{scenario:
    [{"message", "count"[, "example"]}]}``, every distinct kind of message (:func:`message_kind`: a message recorded
    with its seed counts with the others of its kind) with its total count, the most frequent first. Every scenario
    with an errored episode is in it, if only with ``[]``."""
    counts: Dict[str, Dict[str, int]] = {}
    examples: Dict[str, Dict[str, str]] = {}
    for errored in found:
        if errored is None:
            continue
        for name in errored.scenarios or {}:
            counts.setdefault(name, {})
        for name, rows in (errored.messages or {}).items():
            into = counts.setdefault(name, {})
            for row in rows:
                kind = message_kind(row["message"])
                into[kind] = into.get(kind, 0) + int(row["count"])
                example = row.get("example") or (row["message"] if kind != row["message"] else None)
                if example:
                    examples.setdefault(name, {}).setdefault(kind, example)
    return _ranked(counts, examples)


def _episodes(n: int) -> str:
    return f"{n} episode{'s' if n != 1 else ''}"


def _row_text(row: Mapping[str, Any]) -> str:
    """``"worker hung ... seed <seed> (4 episodes, e.g. seed 17)"``: one kind of message with its count and, when
    the kind stands for several seeds, the first one's seed."""
    seed = _SEED.search(str(row.get("example") or ""))
    return f"{row['message']} ({_episodes(int(row['count']))}" + (f", e.g. seed {seed.group(1)})" if seed else ")")


def messages_text(messages: Mapping[str, Sequence[Mapping[str, Any]]], name: str,
                  kept: int = ERROR_MESSAGES_KEPT) -> str:
    """Scenario ``name``'s error messages in words, the ``kept`` most frequent: ``"scene not sampled (3 episodes);
    worker hung ... seed <seed> (2 episodes, e.g. seed 17)"``, then how many more distinct messages there were in
    how many episodes."""
    rows = sorted(messages.get(name) or [], key=lambda row: -int(row["count"]))  # stable: ties keep their order
    parts = [_row_text(row) for row in rows[:kept]]
    rest = rows[kept:]
    if rest:
        parts.append(f"and {len(rest)} more distinct message(s) in {sum(int(row['count']) for row in rest)} "
                     "episode(s)")
    return "; ".join(parts)
