"""The episodes of a loop step that errored, and their error messages counted per scenario.

An errored episode (a scene the scenario's sampler could not produce, a crashed or hung worker...) counts in no rate
and no test; the loop records them per step (:func:`errored_episodes`), says so in its log and lists them in its
reports, each scenario with its distinct error messages and how many episodes ended in each.
"""

from __future__ import annotations

from typing import Any, Dict, List, Mapping, Sequence

__all__ = ["ERROR_MESSAGES_KEPT", "error_message", "errored_episodes", "merged_messages", "messages_text"]

ERROR_MESSAGES_KEPT = 5
"""How many distinct error messages :func:`errored_episodes` keeps per scenario (the most frequent, with counts)."""


def error_message(error: Any) -> str:
    """An episode's error as the loop records it: its first line, cut to 300 characters (``"error"`` when empty)."""
    text = str(error).strip()
    return text.splitlines()[0][:300] if text else "error"


def errored_episodes(records: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    """The episodes of ``records`` that errored (an ``error`` set: a scene that could not be sampled, a crashed or
    hung worker...), which no rate counts: ``{"episodes": n, "scenarios": {scenario: n}, "messages": {scenario:
    [{"message", "count"}]}, "unlisted": {scenario: {"messages", "episodes"}}, "examples": {scenario: its first
    error}}``. ``messages`` holds each scenario's distinct errors (:func:`error_message`) with how many episodes
    ended in each, the :data:`ERROR_MESSAGES_KEPT` most frequent first (ties in the order they came); ``unlisted``
    counts the distinct messages and episodes beyond those, for the scenarios that had more."""
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
            **_message_counts(counts)}


def _message_counts(counts: Mapping[str, Mapping[str, int]]) -> Dict[str, Any]:
    """``messages``, ``unlisted`` and ``examples`` of :func:`errored_episodes` from ``{scenario: {message: count}}``
    (each scenario's messages in the order they came)."""
    messages: Dict[str, List[Dict[str, Any]]] = {}
    unlisted: Dict[str, Dict[str, int]] = {}
    for name in sorted(counts):
        ranked = sorted(counts[name].items(), key=lambda item: -item[1])  # stable: ties keep their order
        messages[name] = [{"message": text, "count": n} for text, n in ranked[:ERROR_MESSAGES_KEPT]]
        rest = ranked[ERROR_MESSAGES_KEPT:]
        if rest:
            unlisted[name] = {"messages": len(rest), "episodes": sum(n for _, n in rest)}
    return {"messages": messages, "unlisted": unlisted,
            "examples": {name: next(iter(counts[name])) for name in sorted(counts)}}


def merged_messages(found: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    """The ``messages`` and ``unlisted`` of several :func:`errored_episodes` (steps, policies) added up per
    scenario; one recorded before messages were counted gives its example once."""
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
    merged = _message_counts(counts)
    for name, more in beyond.items():  # messages unlisted in a step are not compared with those listed elsewhere
        into = merged["unlisted"].setdefault(name, {"messages": 0, "episodes": 0})
        into["messages"] += more["messages"]
        into["episodes"] += more["episodes"]
    return {"messages": merged["messages"], "unlisted": merged["unlisted"]}


def messages_text(messages: Mapping[str, Sequence[Mapping[str, Any]]], unlisted: Mapping[str, Mapping[str, int]],
                  name: str) -> str:
    """Scenario ``name``'s error messages in words: ``"scene not sampled (3 episodes); worker hung (1 episode)"``,
    and how many more distinct messages there were."""
    parts = [f"{row['message']} ({row['count']} episode{'s' if row['count'] != 1 else ''})"
             for row in messages.get(name) or []]
    more = unlisted.get(name)
    if more:
        parts.append(f"and {more['messages']} more distinct message(s) in {more['episodes']} episode(s)")
    return "; ".join(parts)
