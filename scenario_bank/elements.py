"""The semantic-element vocabulary of dv2s-gym and its JSON format.

Every stage speaks it: the video analyzer writes it, the scenario generator reads
it, bank sidecars store it, labels of the evaluation set use it, and the metrics
(SCS, HR, SP, E2E-SC) compare sets of it. A label looks like::

    {"road": "highway",
     "participants": ["ego", "car"],
     "actions": [["car", "brake"]],
     "relations": [["car", "ahead_of", "ego"]]}

* ``road``: one of :data:`ROADS`.
* ``participants``: a multiset (list with repeats) of :data:`PARTICIPANTS`;
  ``["ego", "pedestrian", "pedestrian"]`` is an ego and two pedestrians.
* ``actions``: ``[participant type, action]`` pairs, action from :data:`ACTIONS`.
* ``relations``: ``[participant type, relation, participant type]`` triples,
  relation from :data:`RELATIONS`.

Collisions: every participant of a collision has ``collide`` and one collision type,
``collide_rear_end`` (front to back, same direction), ``collide_head_on`` (front to
front, opposite directions) or ``collide_side`` (anything else: angle, T-bone,
sideswipe). A description saying "a rear-end collision" states ``collide`` and
``collide_rear_end`` for the colliding participants.

In code a record is an :class:`Elements` (:meth:`Elements.from_dict` reads the JSON object above and checks it
against the vocabulary, :meth:`Elements.to_dict` writes it back).

For the metrics a label becomes a set of hashable elements (:func:`element_set`):
``("road", r)``, ``("participant", type, k)`` for the k-th of a type (so counts
matter), ``("action", type, action)`` and ``("relation", a, rel, b)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Dict, FrozenSet, Iterable, List, Mapping, Optional, Tuple, Union

from scenario_bank.errors import DV2SError

__all__ = [
    "Road",
    "ActorKind",
    "Action",
    "Relation",
    "ROADS",
    "PARTICIPANTS",
    "ACTIONS",
    "COLLISION_TYPES",
    "RELATIONS",
    "CAN_DO",
    "ElementError",
    "Elements",
    "element_set",
    "empty_elements",
    "with_undirected",
]



class Road(StrEnum):
    """A road type, one of :data:`ROADS` (in its order); ``str``-valued as :class:`ActorKind` is
    (``Road.MERGE == "merge"``, the on-ramp, which is no :attr:`Action.MERGE`)."""

    HIGHWAY = "highway"
    STRAIGHT_ROAD = "straight_road"
    INTERSECTION = "intersection"
    T_JUNCTION = "t_junction"
    THREE_WAY = "three_way"
    ROUNDABOUT = "roundabout"
    MERGE = "merge"


ROADS = tuple(str(road) for road in Road)
"""The road types of :class:`Road`, as plain strings."""


class ActorKind(StrEnum):
    """The kind of an actor, one of :data:`PARTICIPANTS` (in its order); ``str``-valued, so a kind compares equal to
    its name as the elements spell it (``ActorKind.EGO == "ego"``): code compares kinds with these, never with a
    string spelled out."""

    EGO = "ego"
    CAR = "car"
    TRUCK = "truck"
    BUS = "bus"
    MOTORCYCLE = "motorcycle"
    BICYCLE = "bicycle"
    PEDESTRIAN = "pedestrian"
    OBSTACLE = "obstacle"


PARTICIPANTS = tuple(str(kind) for kind in ActorKind)
"""The kinds of :class:`ActorKind`, as plain strings. Vans, SUVs and pickups are ``car``; scooters and cyclists
ride a ``bicycle``; a motorcyclist a ``motorcycle``."""


class Action(StrEnum):
    """An action of the vocabulary, one of :data:`ACTIONS` (in its order); ``str``-valued as :class:`ActorKind` is
    (``Action.BRAKE == "brake"``): code compares actions with these, never with a string spelled out."""

    BRAKE = "brake"
    STOP = "stop"
    ACCELERATE = "accelerate"
    LANE_CHANGE_LEFT = "lane_change_left"
    LANE_CHANGE_RIGHT = "lane_change_right"
    CUT_IN = "cut_in"
    MERGE = "merge"
    TURN_LEFT = "turn_left"
    TURN_RIGHT = "turn_right"
    CROSS = "cross"
    COLLIDE = "collide"
    KEEP_LANE = "keep_lane"
    GO_STRAIGHT = "go_straight"
    OVERTAKE = "overtake"
    DRIFT = "drift"
    COLLIDE_REAR_END = "collide_rear_end"
    COLLIDE_SIDE = "collide_side"
    COLLIDE_HEAD_ON = "collide_head_on"
    U_TURN = "u_turn"
    """Turning round to drive the opposite way."""
    REVERSE = "reverse"
    """Driving backwards."""
    SWERVE = "swerve"
    """A quick sideways move within or out of the lane that is not a completed lane change."""
    PULL_OUT = "pull_out"
    """Leaving a parking spot, the shoulder or a driveway into the traffic lane."""
    LANE_CHANGE = "lane_change"
    """A lane change whose direction the source does not give (the metrics match it with either
    ``lane_change_left`` or ``lane_change_right``, see :func:`with_undirected`)."""


class Relation(StrEnum):
    """A relation of the vocabulary, one of :data:`RELATIONS` (in its order); ``str``-valued as :class:`ActorKind`
    is (``Relation.AHEAD_OF == "ahead_of"``): code compares relations with these, never with a string spelled out."""

    AHEAD_OF = "ahead_of"
    BEHIND = "behind"
    LEFT_OF = "left_of"
    RIGHT_OF = "right_of"
    ONCOMING = "oncoming"
    SAME_LANE = "same_lane"
    CROSSING_PATH = "crossing_path"


ACTIONS = tuple(str(action) for action in Action)
"""The actions of :class:`Action`, as plain strings (its members say what ``u_turn``, ``reverse``, ``swerve``,
``pull_out`` and ``lane_change`` mean)."""
COLLISION_TYPES = tuple(str(action) for action in (Action.COLLIDE_REAR_END, Action.COLLIDE_SIDE,
                                                   Action.COLLIDE_HEAD_ON))
"""The collision-type actions (each comes with ``collide``)."""
RELATIONS = tuple(str(relation) for relation in Relation)
"""The relations of :class:`Relation`, as plain strings."""

_VEHICLE_ACTIONS = frozenset(ACTIONS)
CAN_DO: Dict[str, FrozenSet[str]] = {
    **{kind: _VEHICLE_ACTIONS for kind in (ActorKind.EGO, ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS,
                                           ActorKind.MOTORCYCLE, ActorKind.BICYCLE)},
    ActorKind.PEDESTRIAN: frozenset(map(str, (Action.CROSS, Action.STOP, Action.COLLIDE, *COLLISION_TYPES))),
    ActorKind.OBSTACLE: frozenset(),
}
"""Participant type -> the actions a participant of that type can do at all, whether a generator builds them or
not: the ego and every vehicle any action; a pedestrian only crosses, stops or collides; an obstacle nothing."""

Element = Tuple[Any, ...]


class ElementError(DV2SError, ValueError):
    """Elements that do not follow the vocabulary."""


_FIELDS = ("road", "participants", "actions", "relations")


@dataclass(frozen=True)
class Elements:
    """The semantic elements of one scene: its ``road`` (one of :data:`ROADS`, or ``None``), its ``participants``
    (a multiset of :data:`PARTICIPANTS`, sorted), its ``actions`` (``(participant type, action)`` pairs) and its
    ``relations`` (``(participant type, relation, participant type)`` triples), each sorted and without repeats.

    Built from any content (lists or tuples, in any order, with repeated actions or relations), a record holds its
    canonical form and checks it against the vocabulary (:class:`ElementError` names the offending entry), so two
    records of the same content compare and hash equal. It is read by its fields; its JSON object is :meth:`to_dict`
    (a record is no mapping: ``elements["actions"]`` is a ``TypeError``). Every record is true, a record of nothing
    too: test for one with ``== Elements()``.
    """

    road: Optional[str] = None
    participants: Tuple[str, ...] = ()
    actions: Tuple[Tuple[str, str], ...] = ()
    relations: Tuple[Tuple[str, str, str], ...] = ()

    def __post_init__(self) -> None:
        if self.road is not None:
            _check(self.road, ROADS, "road type")
        participants = tuple(sorted(_check(p, PARTICIPANTS, "participant") for p in self.participants))
        actions = tuple(sorted({(_check(a[0], PARTICIPANTS, "participant"), _check(a[1], ACTIONS, "action"))
                                for a in _pairs(self.actions, 2, "action")}))
        relations = tuple(sorted({(_check(r[0], PARTICIPANTS, "participant"), _check(r[1], RELATIONS, "relation"),
                                   _check(r[2], PARTICIPANTS, "participant"))
                                  for r in _pairs(self.relations, 3, "relation")}))
        object.__setattr__(self, "participants", participants)
        object.__setattr__(self, "actions", actions)
        object.__setattr__(self, "relations", relations)

    @classmethod
    def from_dict(cls, data: Union["Elements", Mapping[str, Any]]) -> "Elements":
        """The record of ``data``: a JSON object with (some of) the keys ``road``, ``participants``, ``actions``
        and ``relations`` as a label or sidecar holds it, or a record (returned as it is). :class:`ElementError`
        names a field or entry that does not follow the vocabulary."""
        if isinstance(data, cls):
            return data
        if not isinstance(data, Mapping):
            raise ElementError(f"elements must be a JSON object, got {type(data).__name__}")
        unknown = set(data) - set(_FIELDS)
        if unknown:
            raise ElementError(f"unknown element fields {sorted(unknown)}; "
                               "allowed: road, participants, actions, relations")
        return cls(data.get("road"), data.get("participants", []), data.get("actions", []),
                   data.get("relations", []))

    def to_dict(self) -> Dict[str, Any]:
        """The JSON object of the record (a new dict each call): ``road`` (``null`` when ``None``), then
        ``participants``, ``actions`` and ``relations`` as lists."""
        return {"road": self.road, "participants": list(self.participants),
                "actions": [list(a) for a in self.actions], "relations": [list(r) for r in self.relations]}


def empty_elements() -> Elements:
    """An element record with nothing in it."""
    return Elements()


def _check(value: str, allowed: Iterable[str], what: str) -> str:
    if value not in allowed:
        raise ElementError(f"unknown {what} {value!r}; use one of: {', '.join(allowed)}")
    return value


def _pairs(items: Iterable, size: int, what: str) -> List[Tuple[str, ...]]:
    out = []
    for item in items:
        if not isinstance(item, (list, tuple)) or len(item) != size:
            raise ElementError(f"each {what} must be a list of {size} strings, got {item!r}")
        out.append(tuple(item))
    return out


def element_set(data: Union[Elements, Mapping[str, Any]]) -> FrozenSet[Element]:
    """The set of semantic elements of a record (or of its JSON object, such as a label file's), as the metrics
    compare them."""
    record = Elements.from_dict(data)
    elements: set = set()
    if record.road is not None:
        elements.add(("road", record.road))
    counts: Dict[str, int] = {}
    for p in record.participants:
        counts[p] = counts.get(p, 0) + 1
        elements.add(("participant", p, counts[p]))
    elements.update(("action", a, b) for a, b in record.actions)
    elements.update(("relation", a, r, b) for a, r, b in record.relations)
    return frozenset(elements)


_DIRECTED = {str(Action.LANE_CHANGE_LEFT): str(Action.LANE_CHANGE),
             str(Action.LANE_CHANGE_RIGHT): str(Action.LANE_CHANGE)}


def with_undirected(elements: FrozenSet[Element]) -> FrozenSet[Element]:
    """``elements`` plus the undirected form of each directed element it holds.

    A source that says "changes lanes" without a side is labelled ``lane_change``;
    a scenario that changes lanes to the left shows ``lane_change_left``. The metrics
    widen the side they match against (never the side they divide by) with this, so
    the undirected label is matched by either direction and a directed one only by itself.
    """
    extra = {("action", e[1], _DIRECTED[e[2]]) for e in elements if e[0] == "action" and e[2] in _DIRECTED}
    return frozenset(elements) | extra
