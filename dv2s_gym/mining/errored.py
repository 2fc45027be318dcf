"""The episodes of a loop step that errored, and their error messages counted per scenario.

An errored episode (a scene the scenario's sampler could not produce, a crashed or hung worker...) counts in no rate
and no test; the loop records them per step (:func:`errored_episodes`), says so in its log and lists them in its
reports, each scenario with its distinct error messages and how many episodes ended in each.
"""

from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional, Sequence

__all__ = ["ERROR_MESSAGES_KEPT", "error_message", "errored_episodes", "merged_messages", "messages_text"]

ERROR_MESSAGES_KEPT = 5
"""How many distinct error messages a report lists per scenario (the most frequent, with counts; the rest are
counted). The record keeps them all, so the steps of a round add up exactly (:func:`merged_messages`)."""


def error_message(error: Any) -> str:
    """An episode's error as the loop records it: its first line, cut to 300 characters (``"error"`` when empty)."""
    text = str(error).strip()
    return text.splitlines()[0][:300] if text else "error"


def errored_episodes(records: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    """The episodes of ``records`` that errored (an ``error`` set: a scene that could not be sampled, a crashed or
    hung worker...), which no rate counts: ``{"episodes": n, "scenarios": {scenario: n}, "messages": {scenario:
    [{"message", "count"}]}, "examples": {scenario: its first error}}``. ``messages`` holds every distinct error of
    each scenario (:func:`error_message`) with how many episodes ended in it, the most frequent first (ties in the
    order they came); :func:`messages_text` lists the :data:`ERROR_MESSAGES_KEPT` most frequent and counts the
    rest."""
    scenarios: Dict[str, int] = {}
    counts: Dict[str, Dict[str, int]] = {}
    for record in records:
        error = record.get("error")
        if not error:
            continue
        name = str(record.get("scenario"))
        scenarios[name] = scenarios.get(name, 0) + 1
        found = counts.setdefault(name, {})
        message = error_message(error)
        found[message] = found.get(message, 0) + 1
    return {"episodes": sum(scenarios.values()), "scenarios": dict(sorted(scenarios.items())),
            "messages": _ranked(counts), "examples": {name: next(iter(counts[name])) for name in sorted(counts)}}


def _ranked(counts: Mapping[str, Mapping[str, int]]) -> Dict[str, List[Dict[str, Any]]]:
    """``{scenario: [{"message", "count"}]}`` from ``{scenario: {message: count}}``, every message, the most
    frequent first (ties keep the order they came in)."""
    return {name: [{"message": text, "count": n}
                   for text, n in sorted(counts[name].items(), key=lambda item: -item[1])]
            for name in sorted(counts)}


def merged_messages(found: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    """The ``messages`` of several :func:`errored_episodes` (steps, policies) added up per scenario, every distinct
    message with its total count. One recorded before messages were counted gives its example once; one recorded
    when only the five most frequent were kept brings its ``unlisted`` count of the rest, which is added to
    ``unlisted`` as it is (its messages unknown, they cannot be matched with those listed elsewhere)."""
    counts: Dict[str, Dict[str, int]] = {}
    beyond: Dict[str, Dict[str, int]] = {}
    for errored in found:
        errored = errored or {}
        listed = errored.get("messages")
        if listed is None:  # recorded with its first error only
            listed = {name: [{"message": why, "count": 1}] for name, why in (errored.get("examples") or {}).items()}
        for name, rows in listed.items():
            into = counts.setdefault(name, {})
            for row in rows:
                into[row["message"]] = into.get(row["message"], 0) + int(row.get("count") or 0)
        for name, more in (errored.get("unlisted") or {}).items():
            into = beyond.setdefault(name, {"messages": 0, "episodes": 0})
            into["messages"] += int(more.get("messages") or 0)
            into["episodes"] += int(more.get("episodes") or 0)
    return {"messages": _ranked(counts), "unlisted": beyond}


def messages_text(messages: Mapping[str, Sequence[Mapping[str, Any]]],
                  unlisted: Optional[Mapping[str, Mapping[str, int]]], name: str, kept: int = ERROR_MESSAGES_KEPT) -> str:
    """Scenario ``name``'s error messages in words, the ``kept`` most frequent: ``"scene not sampled (3 episodes);
    worker hung (1 episode)"``, and how many more distinct messages there were in how many episodes (with those an
    older record counted without their text, ``unlisted``)."""
    rows = sorted(messages.get(name) or [], key=lambda row: -int(row["count"]))  # stable: ties keep their order
    parts = [f"{row['message']} ({row['count']} episode{'s' if row['count'] != 1 else ''})" for row in rows[:kept]]
    rest = rows[kept:]
    more = {"messages": len(rest), "episodes": sum(int(row["count"]) for row in rest)}
    for key, value in ((unlisted or {}).get(name) or {}).items():
        more[key] = more.get(key, 0) + int(value or 0)
    if more["messages"]:
        parts.append(f"and {more['messages']} more distinct message(s) in {more['episodes']} episode(s)")
    return "; ".join(parts)
