"""Keep a failure's description to the collisions its trace records.

The Driving Record Analyzer reads a failure video from its pixels alone, and a video can suggest a collision
that never happened: highway-env paints every vehicle and object of a collision red, so an obstacle the ego
hits turns into a red box the ``bev`` analyzer may take for a crashed car, and a nearby car that turned red
may be read as the ego's crash partner. A mined failure's trace records every collision (the ego's and the
other actors'), so the description of a mined failure is held to it: a sentence (or its ``and crashes``
phrase) that states a collision between kinds of actors the trace never saw collide is taken out; everything
else the analyzer said stays, and the trace's own account of the failure is added after it
(:func:`~dv2s_gym.mining.conversion.interaction.interaction_sentence`).

A collision claim is what :func:`~dv2s_gym.pipeline.semantics.text.parse_description` reads from one sentence
alone: an actor kind that collides, with the kind it collides with when the sentence says (or implies) it.
It agrees with the trace when the trace has a collision between those two kinds (without a partner: any
collision of that kind). Descriptions of videos without a trace (the evaluation sets) are not touched.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import FrozenSet, List, Optional, Tuple

from dv2s_gym.mining.conversion.interaction import interaction_sentence
from dv2s_gym.pipeline.semantics.text import elements_from_text, parse_description
from dv2s_gym.pipeline.semantics.trace import trace_actor_kind
from scenario_bank.elements import Action

__all__ = ["TracedDescription", "trace_collision_kinds", "collision_claims", "untraced_claims",
           "keep_traced_collisions", "failure_description"]

_SENTENCE_END = re.compile(r"(?<=[.!?])\s+")
_CRASH_PHRASE = re.compile(
    r",?\s+and\s+(?:then\s+)?(?:suddenly\s+)?(?:crash(?:es)?|collides?(?:\s+with\s+[^,.;!?]*?)?)"
    r"(?=\s+and\b|[,.;!?]|$)", re.IGNORECASE)

Claim = Tuple[str, Optional[str]]
"""A collision a sentence states: ``(kind, partner kind or None)``; the ego's kind is ``ego``."""


def trace_collision_kinds(trace) -> FrozenSet[FrozenSet[str]]:
    """The collisions of ``trace`` (an :class:`~envs.trace.EpisodeTrace`) as pairs of actor kinds
    (``frozenset({"ego", "obstacle"})``; two cars: ``frozenset({"car"})``), from its ``collision`` events."""
    pairs = set()
    for event in getattr(trace, "events", None) or []:
        if event.get("kind") != "collision":
            continue
        kinds = ["ego" if name == "ego" else trace_actor_kind(trace, name) for name in event.get("actors") or []]
        if kinds:
            pairs.add(frozenset(kinds))
    return frozenset(pairs)


def _kind_of(value) -> Optional[str]:
    if value is None:
        return None
    return str(getattr(value, "kind", value))


def collision_claims(sentence: str) -> List[Claim]:
    """The collisions ``sentence`` states, read alone (:func:`parse_description`): one ``(kind, partner kind)``
    per actor that collides (the partner ``None`` when the sentence names none)."""
    claims: List[Claim] = []
    for entity in parse_description(sentence).entities:
        if entity.has(Action.COLLIDE):
            claim = (str(entity.kind), _kind_of(entity.detail(Action.COLLIDE).get("with")))
            if claim not in claims:
                claims.append(claim)
    return claims


def _traced(claim: Claim, collisions: FrozenSet[FrozenSet[str]]) -> bool:
    kind, partner = claim
    if partner is None:
        return any(kind in pair for pair in collisions)
    return frozenset((kind, partner)) in collisions


def untraced_claims(sentence: str, collisions: FrozenSet[FrozenSet[str]]) -> List[Claim]:
    """The collision claims of ``sentence`` (:func:`collision_claims`) that none of ``collisions``
    (:func:`trace_collision_kinds`) backs."""
    return [claim for claim in collision_claims(sentence) if not _traced(claim, collisions)]


@dataclass
class TracedDescription:
    """A description held to its trace's collisions (:func:`keep_traced_collisions`).

    Attributes:
        text: the description without the collisions the trace does not record (and, from
            :func:`failure_description`, with the trace's account of the failure added).
        removed: what was taken out of the original text (whole sentences, or ``and crashes`` phrases), in order.
        events: the trace's account of the failure that was added (``""``: none).
    """

    text: str
    removed: List[str]
    events: str = ""


def keep_traced_collisions(text: str, trace) -> TracedDescription:
    """``text`` (a failure video's description) without the collisions ``trace`` does not record.

    Each sentence is read alone; when it states a collision the trace has no counterpart of
    (:func:`untraced_claims`), its ``and crashes`` / ``and collides with ...`` phrase is taken out, and when
    the sentence still states one, the whole sentence is. Sentences that agree with the trace are kept word
    for word, so a description that states no untraced collision comes back unchanged."""
    collisions = trace_collision_kinds(trace)
    kept: List[str] = []
    removed: List[str] = []
    for sentence in _SENTENCE_END.split(text.strip()):
        if not sentence or not untraced_claims(sentence, collisions):
            if sentence:
                kept.append(sentence)
            continue
        shorter = _CRASH_PHRASE.sub("", sentence)
        if shorter != sentence and not untraced_claims(shorter, collisions):
            removed.extend(m.group(0).strip(" ,") for m in _CRASH_PHRASE.finditer(sentence))
            kept.append(shorter)
        else:
            removed.append(sentence)
    return TracedDescription(" ".join(kept) if removed else text, removed)


def failure_description(text: str, trace, interaction=None) -> TracedDescription:
    """A mined failure's description from what the Driving Record Analyzer said of its video (``text``): the
    collisions ``trace`` does not record taken out (:func:`keep_traced_collisions`), then, when ``interaction``
    (the failure's :class:`~dv2s_gym.mining.conversion.interaction.FailureInteraction`, or its JSON object) is
    given, the trace's account of it added (:func:`~dv2s_gym.mining.conversion.interaction.interaction_sentence`:
    the failure's actor, its manoeuvre and its collision with the ego, unless the kept text already says them)."""
    traced = keep_traced_collisions(text, trace)
    if interaction is None:
        return traced
    events = interaction_sentence(interaction, known=elements_from_text(traced.text))
    if events:
        traced.text = f"{traced.text.strip()} {events}"
        traced.events = events
    return traced
