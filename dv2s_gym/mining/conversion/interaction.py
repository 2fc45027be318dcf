"""The interaction behind a failure, read from the failure's own trace.

A failure is more than its type: the policy failed *because of* some actor doing something. This module
finds that actor in an :class:`~envs.trace.EpisodeTrace` and what it did, so a scenario generated from the
failure can be judged on whether it holds the same interaction (:func:`shows_interaction`), and so the
description of a failure video names it (:func:`interaction_sentence`) even when the actor was outside
the rendered frame.

The **key actor** (:func:`key_actor`):

* a ``collision``: the ego's collision partner (the failure's ``with``, else the collision event's);
* a ``low_ttc``: the actor of the smallest time-to-collision (the failure's ``with``);
* a ``stall``, an ``off_road`` or anything else: the actor nearest ahead of the ego in its lane during
  the :data:`LOOKBACK_S` seconds up to the failure (the one the ego slowed down for), however far
  ahead; when no actor was ahead in the lane, the actor nearest to the ego in that window.

Its **manoeuvres** are the actions the project's trace semantics
(:func:`dv2s_gym.pipeline.semantics.trace.elements_from_trace`, the same rules as the E2E-SC metric)
give that actor alone with the ego, restricted to :data:`MANOEUVRES` (braking, stopping, lane changes,
cut-ins, merges, crossings...); keeping its lane is no manoeuvre.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, List, Mapping, Optional, Tuple

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.semantics.trace import ego_frame, elements_from_trace, trace_actor_kind
from scenario_bank.elements import Action, ActorKind, Elements, Relation
from scenario_bank.failure_types import failure_type, is_contact
from scenario_bank.records import Failure, JsonRecord

__all__ = ["MANOEUVRES", "LOOKBACK_S", "FailureInteraction", "key_actor", "actor_manoeuvres", "failure_interaction",
           "shows_interaction", "trace_shows_interaction", "interaction_sentence"]

MANOEUVRES = tuple(str(action) for action in (
    Action.CUT_IN, Action.CROSS, Action.MERGE, Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT, Action.BRAKE,
    Action.STOP, Action.PULL_OUT, Action.DRIFT, Action.SWERVE, Action.TURN_LEFT, Action.TURN_RIGHT, Action.U_TURN,
    Action.REVERSE, Action.OVERTAKE))
"""The actions that make an actor's part in a failure, most telling first."""
LOOKBACK_S = 6.0
"""Seconds before the failure searched for the actor the ego reacted to (stalls, leaving the road)."""
_SAME_LANE_M = 2.0   # |lateral offset| [m] within which an actor is in the ego's lane
_LANE_CHANGES = frozenset({Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT})


def _frequency(trace) -> float:
    return float((trace.config or {}).get("policy_frequency") or 5)


def _failure_step(trace, step: Optional[int], time: Optional[float]) -> int:
    """The trace's step of a failure at ``step`` (else at ``time`` [s]; neither: the last step)."""
    last = max(0, len(trace.states) - 1)
    if step is not None:
        return max(0, min(last, int(step)))
    if time is not None:
        return max(0, min(last, int(round(float(time) * _frequency(trace)))))
    return last


def _step_of(trace, failure: Optional[Failure]) -> int:
    """The trace's step of ``failure`` (without one: the last step)."""
    return _failure_step(trace, failure.step, failure.time) if failure is not None else _failure_step(trace, None, None)


def key_actor(trace, failure: Optional[Failure]) -> Optional[str]:
    """The name of the actor the failure involved (see the module doc), or None when the ego was alone."""
    if not trace.states:
        return None
    names = [n for n in trace.states[0] if n != "ego"]
    kind = failure.type if failure is not None else None
    partner = failure.with_ if failure is not None else None
    if is_contact(kind) and partner is None:
        event = trace.ego_collision()
        partner = trace.other_actor(event) if event is not None else None
    row = failure_type(str(kind))
    if partner is not None and partner in names and row is not None and row.with_actor:
        return partner
    k = _step_of(trace, failure)
    ahead: Dict[str, float] = {}
    near: Dict[str, float] = {}
    for step in _lookback(trace, k):
        ego = step.get("ego")
        if ego is None:
            continue
        for name in names:
            if name not in step:
                continue
            lon, left = ego_frame(ego, step[name])
            near[name] = min(near.get(name, math.inf), math.hypot(lon, left))
            if lon > 0 and abs(left) <= _SAME_LANE_M:
                ahead[name] = min(ahead.get(name, math.inf), lon)
    pool = ahead or near
    return min(pool, key=lambda n: (pool[n], n)) if pool else None


def actor_manoeuvres(trace, name: str) -> List[str]:
    """The :data:`MANOEUVRES` actor ``name`` performs in ``trace``, judged alone with the ego by the trace
    semantics' rules (in :data:`MANOEUVRES` order)."""
    keep = {"ego", name}
    alone = dataclasses.replace(
        trace, states=[{k: v for k, v in step.items() if k in keep} for step in trace.states],
        events=[e for e in trace.events if set(e.get("actors") or []) <= keep])
    kind = trace_actor_kind(trace, name)
    found = {action for who, action in elements_from_trace(alone).actions if who == kind}
    return [m for m in MANOEUVRES if m in found]


@dataclass(frozen=True, eq=False)
class FailureInteraction(JsonRecord):
    """A failure's interaction (:func:`failure_interaction`), as a conversion's record and a mined bank entry's
    provenance (``interaction``) hold it: the ``failure_type``, the key ``actor`` (``None``: the ego was alone), its
    ``kind``, its ``manoeuvres``, its ``gap_m`` ahead of the ego and its ``side``. Every field is written, ``null``
    when unknown."""

    failure_type: Optional[str] = None
    actor: Optional[str] = None
    kind: Optional[str] = None
    manoeuvres: Tuple[str, ...] = ()
    gap_m: Optional[float] = None
    side: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"failure_type": "any", "actor": "any", "kind": "any",
                                                               "manoeuvres": "list"}
    _WHAT: ClassVar[str] = "interaction"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"failure_type", "actor", "kind", "gap_m", "side"})


def failure_interaction(trace, failure: Optional[Failure]) -> FailureInteraction:
    """The failure's interaction (:class:`FailureInteraction`: failure type, key actor, kind, manoeuvres, gap,
    side).

    ``actor`` is the key actor's name (None: the ego was alone), ``kind`` its participant type (the trace's
    ``kinds``; else the failure's ``with_kind``; else guessed from the name),
    ``manoeuvres`` what it did, ``gap_m`` its distance ahead of the ego (metres along the ego's heading) when
    first seen in the :data:`LOOKBACK_S` seconds up to the failure, ``side`` where it was then
    (``"same_lane"``, ``"left"``, ``"right"``).
    """
    name = key_actor(trace, failure)
    out = FailureInteraction(failure_type=failure.type if failure is not None else None, actor=name)
    if name is None:
        return out
    known = dict(getattr(trace, "kinds", {}) or {})
    kind = known[name] if name in known else (
        failure.with_kind if failure is not None and failure.with_ == name and failure.with_kind
        else trace_actor_kind(trace, name))
    out = out.replace(kind=kind, manoeuvres=tuple(actor_manoeuvres(trace, name)))
    seen = _first_seen(trace, name, _step_of(trace, failure))
    return out if seen is None else out.replace(gap_m=round(seen[0], 1), side=seen[1])


def _lookback(trace, k: int) -> List[Dict[str, Any]]:
    """The trace's states of the :data:`LOOKBACK_S` seconds up to step ``k``, ``k`` included."""
    return trace.states[max(0, k - int(round(LOOKBACK_S * _frequency(trace)))):k + 1]


def _first_seen(trace, name: str, k: int) -> Optional[Tuple[float, str]]:
    """``(distance ahead of the ego, side)`` of actor ``name`` when first seen in :func:`_lookback` up to step ``k``
    (side: ``"same_lane"``, ``"left"``, ``"right"``); ``None`` when it is not seen there."""
    for step in _lookback(trace, k):
        if "ego" in step and name in step:
            lon, left = ego_frame(step["ego"], step[name])
            return lon, "same_lane" if abs(left) <= _SAME_LANE_M else ("left" if left > 0 else "right")
    return None


def shows_interaction(interaction: FailureInteraction, elements: Elements) -> bool:
    """Whether simulated ``elements`` (a trace's, :func:`~dv2s_gym.pipeline.semantics.trace.elements_from_trace`)
    hold the interaction: a participant of the key actor's kind doing one of its manoeuvres (a lane change
    in either direction matches a lane change), and, for a collision, that kind colliding. An interaction
    without a key actor is shown by any elements (a JSON object of one is read as a :class:`FailureInteraction`)."""
    interaction = FailureInteraction.from_dict(interaction)
    kind = interaction.kind
    if kind is None:
        return True
    if kind not in elements.participants:
        return False
    actions = {action for who, action in elements.actions if who == kind}
    if is_contact(interaction.failure_type) and Action.COLLIDE not in actions:
        return False
    wanted = set(interaction.manoeuvres or ())
    if not wanted:
        return True
    if wanted & _LANE_CHANGES and actions & _LANE_CHANGES:
        return True
    return bool(wanted & actions)


def trace_shows_interaction(interaction: FailureInteraction, trace) -> bool:
    """Whether an episode's ``trace`` holds the interaction with one actor doing all of it: an actor of the key
    actor's kind that performs one of its manoeuvres (:func:`actor_manoeuvres`, judged alone with the ego; a lane
    change in either direction matches a lane change) and, for a collision, is the actor the ego collided with.
    The actor must also be on the interaction's ``side`` of the ego (same lane, left, right) when first seen in the
    seconds up to the failure, or the end. Stricter than :func:`shows_interaction` on the trace's elements, where one
    car's manoeuvre and another car's collision together would do. An interaction without a key actor is shown by
    any trace."""
    interaction = FailureInteraction.from_dict(interaction)
    kind = interaction.kind
    if kind is None:
        return True
    names = [name for name in (trace.states[0] if trace.states else {}) if name != "ego"]
    if is_contact(interaction.failure_type):
        partners = {trace.other_actor(event) for event in trace.events
                    if event.get("kind") == "collision" and "ego" in event.get("actors", [])}
        names = [name for name in names if name in partners]
    wanted = set(interaction.manoeuvres or ())
    for name in names:
        if trace_actor_kind(trace, name) != kind:
            continue
        if interaction.side is not None and _side_at_failure(trace, name) != interaction.side:
            continue  # a car beside the ego is not the car ahead in its lane that the failure was about
        done = set(actor_manoeuvres(trace, name))
        if not wanted or wanted & done or (wanted & _LANE_CHANGES and done & _LANE_CHANGES):
            return True
    return False


def _side_at_failure(trace, name: str) -> Optional[str]:
    """Where actor ``name`` was beside the ego (:func:`_first_seen`) up to the ego's first failure event, or the
    episode's end: as :func:`failure_interaction` reads a failure's ``side``."""
    event = trace.first_failure_event()
    seen = _first_seen(trace, name, _failure_step(trace, None, float(event.get("time", 0.0)) if event else None))
    return None if seen is None else seen[1]


_ARTICLE = {ActorKind.OBSTACLE: "An obstacle", ActorKind.EGO: "The ego vehicle"}


def interaction_sentence(interaction: FailureInteraction, known: Optional[Elements] = None) -> str:
    """One or two sentences naming the key actor and what it did (from the trace), for the description of a
    failure video; empty when the ego was alone. ``known``: the elements a description already states; what
    they hold (the actor's kind doing one of its manoeuvres, or, for an actor that did none, its kind where it
    was; its collision) is not said again. A JSON object of one is read as a :class:`FailureInteraction`."""
    interaction = FailureInteraction.from_dict(interaction)
    kind = interaction.kind
    if kind is None:
        return ""
    known = known or Elements()
    said = {action for who, action in known.actions if who == kind}
    placed = {relation for who, relation, _ in known.relations if who == kind}
    moves = list(interaction.manoeuvres or ())
    collided = is_contact(interaction.failure_type)
    relation = {Relation.SAME_LANE: Relation.SAME_LANE, Lane.LEFT: Relation.LEFT_OF, Lane.RIGHT: Relation.RIGHT_OF}.get(
        interaction.side)
    if moves and set(moves) & said or not moves and relation in placed:
        return f"The ego vehicle collides with the {kind}." if collided and Action.COLLIDE not in said else ""
    subject = _ARTICLE.get(kind, f"A {kind}")
    gap, side = interaction.gap_m, interaction.side
    where = f" about {abs(gap):.0f} m {'ahead of' if gap >= 0 else 'behind'} the ego vehicle" if gap is not None else ""
    if kind == ActorKind.PEDESTRIAN or Action.CROSS in moves:
        text = f"{subject} crosses the road in front of the ego vehicle."
    elif Action.CUT_IN in moves or Action.MERGE in moves:
        lane = f" from the lane to the {side} of the ego vehicle" if side in (Lane.LEFT, Lane.RIGHT) else ""
        text = f"{subject}{lane} cuts into the ego's lane{where}."
    elif moves and moves[0] in _LANE_CHANGES:
        direction = moves[0].rsplit("_", 1)[1]
        text = f"{subject}{where} changes lanes to the {direction}."
    elif Action.BRAKE in moves:
        lane = " in the ego's lane" if side == Relation.SAME_LANE else ""
        text = f"{subject}{lane}{where} suddenly brakes hard" + (" and stops." if Action.STOP in moves else ".")
    elif Action.STOP in moves:
        text = f"{subject} stands still in the ego's lane{where}." if side == Relation.SAME_LANE else \
            f"{subject}{where} stands still."
    elif side == Relation.SAME_LANE:
        text = f"{subject} drives in the ego's lane{where}."
    else:
        text = f"{subject} drives{where} in the lane to the {side} of the ego vehicle." if side else \
            f"{subject} drives near the ego vehicle."
    if collided and Action.COLLIDE not in said:
        text += f" The ego vehicle collides with the {kind}."
    return text
