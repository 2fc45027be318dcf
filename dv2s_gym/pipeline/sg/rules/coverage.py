"""What a composed script shows against what the description says: the main event, typed collisions, and
``not built`` / ``not shown`` warnings."""

from __future__ import annotations

from typing import Any, Callable, Dict, FrozenSet, List, Optional, Sequence, Tuple

from dv2s_gym.pipeline.errors import GenerationError
from dv2s_gym.pipeline.semantics.parsed import Entity, ParsedDescription
from dv2s_gym.pipeline.sg.rules.describe import COLLISION_HINTS
from dv2s_gym.pipeline.sg.rules.roads import MAP_ROADS
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import (ACTIONS, CAN_DO, PARTICIPANTS, RELATIONS, ROADS, Action, ActorKind, Elements,
                                    element_set, with_undirected)

__all__ = ["check_main_event", "typed_collisions", "unbuilt_warnings", "absent_warnings", "unshown_warnings"]


def _main_event(parsed: ParsedDescription) -> Optional[Tuple[Entity, str]]:
    """The first action of the first non-ego actor that has one, else the ego's first action.

    Only actions a participant of that kind can do count (a parse such as 'pedestrian go straight' is already a
    warning, not an event)."""
    def first(entity: Entity) -> Optional[str]:
        for action, _ in entity.actions:
            if not action.endswith("_pending") and action in CAN_DO.get(entity.kind, ()):
                return action
        return None

    for entity in parsed.entities:
        if entity.kind != ActorKind.EGO and first(entity):
            return entity, first(entity)
    ego = parsed.ego
    if ego is not None and first(ego):
        return ego, first(ego)
    return None


def _lane_changed(shown: FrozenSet[str], s: Script, kind: str) -> bool:
    return bool(shown & {Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT})


def _merged(shown: FrozenSet[str], s: Script, kind: str) -> Optional[bool]:
    """The ego's merge, built as a lane change, is shown by one."""
    return _lane_changed(shown, s, kind) if kind == ActorKind.EGO and s.merged_as_lane_change else None


def _collided(shown: FrozenSet[str], s: Script, kind: str) -> bool:
    return Action.COLLIDE in shown


def _swerved_for_cut_in(shown: FrozenSet[str], s: Script, kind: str) -> Optional[bool]:
    """A swerve toward the ego and back, built as a swerve (warned), shows the cut-in."""
    return True if Action.SWERVE in shown and Action.CUT_IN not in shown else None


_PLACED_BY_ACTION: Dict[str, Callable[[FrozenSet[str], Script, str], Optional[bool]]] = {
    Action.LANE_CHANGE: _lane_changed, Action.MERGE: _merged, Action.CUT_IN: _swerved_for_cut_in,
    **{typed: _collided for typed in COLLISION_HINTS},
}
"""Main-event action -> whether the actions the script builds for the actor show it (``None``: the action itself
must be among them)."""


def check_main_event(parsed: ParsedDescription, s: Script) -> None:
    """Raise :class:`GenerationError` when the script does not show the main event (what it was composed to
    show, :attr:`Script.actions`)."""
    main = _main_event(parsed)
    if main is None:
        return
    entity, action = main
    kind = "ego" if entity.kind == ActorKind.EGO else entity.kind
    shown = frozenset(a for k, a in s.actions if k == kind)
    placed = _PLACED_BY_ACTION.get(action)
    placed_it = placed(shown, s, kind) if placed is not None else None
    if placed_it is None:
        placed_it = action in shown
    if not placed_it:
        noun = entity.attrs.get("noun", entity.kind) if entity.kind != ActorKind.EGO else "ego"
        raise GenerationError(
            f"cannot place the main event '{noun} {action.replace('_', ' ')}' of the description: the rules SG "
            f"has no block for it on the chosen road; describe it with a supported manoeuvre (e.g. brake, stop, "
            f"lane change, cut in, turn, cross, collide) or another road")


def typed_collisions(s: Script) -> None:
    """The script means the collision type the text gives wherever it means the collision itself."""
    for actor in [s.frame.ego, *s.frame.actors]:
        kind = "ego" if actor.name == "ego" else actor.kind
        typed = actor.details.get(Action.COLLIDE, {}).get("type")
        if typed and (kind, Action.COLLIDE) in s.actions:
            s.actions.add((kind, typed))


def _words(element: Tuple) -> str:
    return " ".join(str(x) for x in element[1:] if not isinstance(x, int)).replace("_", " ")


def unbuilt_warnings(parsed: ParsedDescription, s: "Script", said: Sequence[str] = ()) -> List[str]:
    """One ``not built: <element> (<phrase>)`` warning per element of the parsed description that the
    composed script does not mean to show (its :attr:`Script.actions`, relations and participants), unless a
    warning in ``said`` already names it. The phrase is the text the parser read the element from (the actor's
    noun when it has none)."""
    meant = with_undirected(element_set(Elements(MAP_ROADS.get(s.frame.map), tuple(s.participants),
                                                 tuple(s.actions), tuple(s.relations))))
    said_text = " ".join(w.lower().replace("_", " ") for w in said)
    phrases: Dict[Tuple, str] = {}
    for entity in parsed.entities:
        noun = "ego" if entity.kind == ActorKind.EGO else str(entity.attrs.get("noun", entity.kind))
        for action, detail in entity.actions:
            phrases.setdefault(("action", entity.kind, action), str(detail.get("phrase") or noun))
        for rel, other in entity.relations:
            phrases.setdefault(("relation", entity.kind, rel, other.kind), noun)
    out: List[str] = []
    described = set()
    for entity in parsed.entities:
        if entity.kind not in PARTICIPANTS:
            continue  # an unknown kind is warned about already
        count = entity.count if entity.kind != ActorKind.EGO else 1
        described.update(("participant", entity.kind, i + 1) for i in range(count))
        described.update(("action", entity.kind, a) for a, _ in entity.actions if a in ACTIONS)
        described.update(("relation", entity.kind, r, o.kind) for r, o in entity.relations
                         if o is not entity and o.kind in PARTICIPANTS and r in RELATIONS)
    if parsed.road in ROADS:
        described.add(("road", parsed.road))
    for element in sorted(described, key=str):
        if element in meant:
            continue
        if element[0] == "road":
            phrase = " ".join(parsed.road_words) or str(element[1])
            built = MAP_ROADS.get(s.frame.map, s.frame.map).replace("_", " ")
            out.append(f"not built: road {_words(element)} ('{phrase}'): the script uses map {s.frame.map} "
                       f"(road type {built})")
            continue
        elif element[0] == "participant":
            phrase = element[1]
        else:
            phrase = phrases.get(element, element[1])
        words = _words(element)
        if words in said_text or element[0] == "action" and f"{element[1]} {element[2].replace('_', ' ')}" in \
                said_text or element[0] == "action" and f"'{element[2].replace('_', ' ')}'" in said_text:
            continue
        out.append(f"not built: {element[0]} {words} ('{phrase}')")
    return out


def absent_warnings(parsed: ParsedDescription) -> List[str]:
    """What the script did with the participants the text says are not there ("no other vehicles")."""
    if not parsed.absent:
        return []
    said = ", ".join(f"'{p}'" for p in getattr(parsed, "absent_phrases", []) or []) or "absent"
    kinds = list(dict.fromkeys(parsed.absent))
    present = sorted({e.kind for e in parsed.entities if e.kind in kinds})
    missing = ", ".join(k for k in kinds if k not in present)
    note = (f"read {said}: the script adds no background traffic, so no {missing}"
            " is placed")
    if present:
        note += f"; the text also describes a {' and a '.join(present)}, which is placed"
    return [note]


def unshown_warnings(meant: Optional[Elements], simulated: Optional[Elements]) -> List[str]:
    """One ``not shown in the simulated run: <element>`` warning per element the script was composed to show
    (``meant``, :attr:`SGResult.elements`) that a simulated run of it did not show (``simulated``, from
    :func:`dv2s_gym.pipeline.semantics.trace.elements_from_trace`)."""
    shown = with_undirected(element_set(simulated or Elements()))
    return [f"not shown in the simulated run: {e[0]} {_words(e)}"
            for e in sorted(element_set(meant or Elements()), key=str) if e not in shown]
