"""What the description parser (:mod:`dv2s_gym.pipeline.semantics.text`) returns: the scene's entities
(:class:`Entity`) and the whole parse (:class:`ParsedDescription`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Dict, List, Optional, Tuple

from scenario_bank.elements import ActorKind, Elements

__all__ = ["Lane", "Entity", "NO_JUNCTION_WORDS", "drift_side", "ParsedDescription"]


class Lane(StrEnum):
    """The lane a description puts a participant in (:attr:`Entity.lane`), relative to the road's lanes; ``str``-valued
    as ``scenario_bank.elements.ActorKind`` is (``Lane.RAMP == "ramp"``)."""

    LEFT = "left"
    MIDDLE = "middle"
    RIGHT = "right"
    ADJACENT = "adjacent"
    """A lane next to the ego's, its side not said."""
    RAMP = "ramp"
    """The on-ramp's acceleration lane."""


@dataclass
class Entity:
    """One participant (or a group of same-type participants) of the described scene."""

    kind: str
    count: int = 1
    descriptors: set = field(default_factory=set)
    actions: List[Tuple[str, Dict[str, Any]]] = field(default_factory=list)
    relations: List[Tuple[str, "Entity"]] = field(default_factory=list)
    lane: Optional[str] = None
    attrs: Dict[str, Any] = field(default_factory=dict)

    def add_action(self, action: str, **detail: Any) -> None:
        for existing, d in self.actions:
            if existing == action:
                for k, v in detail.items():
                    if v and not d.get(k):
                        d[k] = v
                    elif k == "directions" and v:
                        d.setdefault("directions", [])
                return
        self.actions.append((action, dict(detail)))

    def has(self, action: str) -> bool:
        return any(a == action for a, _ in self.actions)

    def detail(self, action: str) -> Dict[str, Any]:
        for a, d in self.actions:
            if a == action:
                return d
        return {}


NO_JUNCTION_WORDS = re.compile(r"\b(?:intersections?|junctions?|crossroads?)\b")
_DRIFT_ONCOMING = re.compile(r"\b(?:centre|center|middle|dividing|median|double) (?:line|marking)s?\b|"
                             r"\b(?:oncoming|opposite|opposing|wrong)\b")
_DRIFT_SIDE = re.compile(r"\b(?:to(?:wards?)?|into|onto|off|on|over) (?:the |its |their )?(?:\w+ ){0,2}?"
                         r"(left|right)\b|\b(left|right)(?: hand)? (?:edge|shoulder|kerb|curb|lane|side)\b")


def drift_side(text: str) -> Optional[str]:
    """The side a drift goes to, from the words after it: across the centre line / into the oncoming lane is
    left (right-hand traffic), "toward the road edge on the right" / "into the left lane" say it; else None."""
    if _DRIFT_ONCOMING.search(text):
        return "left"
    m = _DRIFT_SIDE.search(text)
    return (m.group(1) or m.group(2)) if m else None


@dataclass
class ParsedDescription:
    """What a description says: road, entities (ego first when mentioned), unknowns."""

    text: str
    road: Optional[str] = None
    road_words: List[str] = field(default_factory=list)
    entities: List[Entity] = field(default_factory=list)
    unknown_actors: List[str] = field(default_factory=list)
    unresolved: List[str] = field(default_factory=list)
    features: Dict[str, Any] = field(default_factory=dict)
    """Road features said in the text (see :func:`dv2s_gym.pipeline.semantics.road.road_features`)."""
    absent: List[str] = field(default_factory=list)
    """Participant kinds the text says are not there ("no other vehicles")."""
    absent_phrases: List[str] = field(default_factory=list)
    """The words that said so ("no other vehicles")."""
    unplaced: List[str] = field(default_factory=list)
    """Phrases (verbatim clauses) the parser could not place; the generator warns about each."""

    @property
    def ego(self) -> Optional[Entity]:
        for e in self.entities:
            if e.kind == ActorKind.EGO:
                return e
        return None

    def index(self, entity: Entity) -> int:
        for i, e in enumerate(self.entities):
            if e is entity:
                return i
        raise ValueError("entity not in description")

    def elements(self) -> Elements:
        """The semantic elements of the description."""
        participants: List[str] = []
        for e in self.entities:
            participants.extend([e.kind] * e.count)
        actions = sorted({(e.kind, a) for e in self.entities for a, _ in e.actions})
        relations = set()
        for e in self.entities:
            for rel, other in e.relations:
                if other is e:
                    continue
                relations.add((e.kind, rel, other.kind))
        return Elements(self.road, tuple(participants), tuple(actions), tuple(sorted(relations)))
