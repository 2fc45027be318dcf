"""What happened in a failure: who was involved and what each side was doing just before it.

:func:`extract_behaviour` reads an episode's trace (:class:`~envs.trace.EpisodeTrace`: every actor's
``[x, y, heading, speed]`` after every step, and each actor's kind) and its
:class:`~dv2s_gym.mining.monitors.Failure`, and returns a :class:`Behaviour` (a record of
:mod:`scenario_bank.records`, importable from here too), which the miner keeps in the episode record
(``behaviour``); its JSON object (:meth:`Behaviour.to_dict`)::

    {"actor": kind of the other actor involved ("car", "truck", "pedestrian", ...) or "none",
     "actor_manoeuvre": "crossing" | "oncoming" | "stopped" | "cut_in" | "lane_change" | "braking"
                        | "steady" | "none",
     "ego_manoeuvre": "stopped" | "lane_change" | "braking" | "keeping_lane"}

The manoeuvres are read from the :data:`WINDOW_SECONDS` before the failure step (for a collision, before the
impact: the state logged at the collision's step already carries the speed the impact took away, which is no
braking or stopping of either side):

- the other actor is ``crossing`` when its heading at the failure differs from the ego's by 45 to 135
  degrees, ``oncoming`` beyond 135; else ``stopped`` (below ``STANDING_SPEED`` at the failure),
  ``cut_in`` (it moved sideways by :data:`LATERAL_METRES` or more and ended up ahead of the ego, closer to
  its line), ``lane_change`` (moved sideways otherwise), ``braking`` (lost :data:`BRAKING_DROP` m/s or more)
  or ``steady``;
- the ego is ``stopped``, ``lane_change``, ``braking`` (same thresholds) or ``keeping_lane``.

Sideways motion is measured across the heading at the start of the window, so on a tight curve a
long window can read as a lane change; the bank's roads are mostly straight or gently curved over
two seconds. A ``stall`` (any type whose row says ``standstill``) names the actor the ego stood behind (:func:`actor_ahead`: the nearest one ahead in
the ego's lane, within :data:`WAITING_DISTANCE`, at the stall's start); a stall on a free road, and a failure
without another actor (``off_road``), have actor ``"none"``.

"""

from __future__ import annotations

import math
from typing import Any, Dict, List, Mapping, Optional

from dv2s_gym.mining.monitors import Failure
from scenario_bank.failure_types import is_contact, is_standstill
from scenario_bank.records import UNKNOWN_PART, Behaviour, EpisodeRecord

__all__ = ["Behaviour", "extract_behaviour", "behaviour_of", "actor_ahead", "involved_actor", "WAITING_DISTANCE", "UNKNOWN", "WINDOW_SECONDS", "LATERAL_METRES",
           "BRAKING_DROP", "ACTOR_MANOEUVRES", "EGO_MANOEUVRES"]

WINDOW_SECONDS = 2.0
"""How far back from the failure step the manoeuvres are read."""
LATERAL_METRES = 2.0
"""Sideways motion (across the heading at the window's start) that counts as a lane change (half a lane)."""
BRAKING_DROP = 2.0
"""Speed lost over the window [m/s] that counts as braking."""
STANDING = 0.5
"""m/s under which an actor stands (``envs.safety_metrics.STANDING_SPEED``)."""
ACTOR_MANOEUVRES = ("crossing", "oncoming", "stopped", "cut_in", "lane_change", "braking", "steady", "none")
EGO_MANOEUVRES = ("stopped", "lane_change", "braking", "keeping_lane")
WAITING_DISTANCE = 80.0
"""Metres ahead of a stalled ego within which an actor in its lane counts as the one it stood behind (twice the
stall monitor's free path, :data:`envs.safety_metrics.FREE_PATH`: a stall's path is free that far)."""
LANE_HALF_WIDTH = 2.0
"""Metres to either side of the ego's heading line that count as its lane (half a 4 m lane)."""


UNKNOWN = Behaviour(actor=UNKNOWN_PART, actor_manoeuvre=UNKNOWN_PART, ego_manoeuvre=UNKNOWN_PART)
"""The behaviour of a failure whose record and trace cannot tell it."""


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _lateral(start: List[float], end: List[float]) -> float:
    """Signed sideways motion from ``start`` to ``end`` across ``start``'s heading."""
    dx, dy = end[0] - start[0], end[1] - start[1]
    return -dx * math.sin(start[2]) + dy * math.cos(start[2])


def _window(states: List[Dict[str, List[float]]], name: str, step: int, steps: int) -> List[List[float]]:
    return [s[name] for s in states[max(0, step - steps): step + 1] if name in s]


def _ego_manoeuvre(path: List[List[float]]) -> str:
    if not path:
        return "unknown"
    if path[-1][3] < STANDING:
        return "stopped"
    if abs(_lateral(path[0], path[-1])) >= LATERAL_METRES:
        return "lane_change"
    if path[0][3] - path[-1][3] >= BRAKING_DROP:
        return "braking"
    return "keeping_lane"


def _actor_manoeuvre(path: List[List[float]], ego_path: List[List[float]]) -> str:
    if not path:
        return "unknown"
    end = path[-1]
    if ego_path:
        ego = ego_path[-1]
        relative = abs(_wrap(end[2] - ego[2]))
        if relative > 3 * math.pi / 4:
            return "oncoming"
        if relative > math.pi / 4:
            return "crossing"
    if end[3] < STANDING:
        return "stopped"
    if abs(_lateral(path[0], end)) >= LATERAL_METRES:
        if ego_path:
            ego = ego_path[-1]
            dx, dy = end[0] - ego[0], end[1] - ego[1]
            ahead = dx * math.cos(ego[2]) + dy * math.sin(ego[2])
            offset_end = abs(-dx * math.sin(ego[2]) + dy * math.cos(ego[2]))
            sx, sy = path[0][0] - ego[0], path[0][1] - ego[1]
            offset_start = abs(-sx * math.sin(ego[2]) + sy * math.cos(ego[2]))
            if ahead > 0 and offset_end < offset_start:
                return "cut_in"
        return "lane_change"
    if path[0][3] - end[3] >= BRAKING_DROP:
        return "braking"
    return "steady"


def actor_ahead(states: Mapping[str, List[float]], distance: float = WAITING_DISTANCE,
                half_width: float = LANE_HALF_WIDTH) -> Optional[str]:
    """The nearest actor of one step's ``states`` ahead of the ego in its lane: centre within ``distance`` m
    ahead along the ego's heading and within ``half_width`` m of its heading line; ``None`` when none is."""
    ego = states.get("ego")
    if ego is None:
        return None
    c, s = math.cos(ego[2]), math.sin(ego[2])
    best: Optional[tuple] = None
    for name, state in states.items():
        if name == "ego":
            continue
        dx, dy = state[0] - ego[0], state[1] - ego[1]
        ahead, lateral = dx * c + dy * s, -dx * s + dy * c
        if 0 < ahead <= distance and abs(lateral) < half_width and (best is None or (ahead, name) < best):
            best = (ahead, name)
    return best[1] if best else None


def involved_actor(trace: Any, failure: Optional[Failure]) -> Optional[str]:
    """The other actor ``failure`` involves in ``trace``: the one it names (``with_``), else for a standstill (a
    ``stall``: :attr:`~scenario_bank.failure_types.FailureType.standstill`) the actor the ego stood behind at the stall's start (:func:`actor_ahead`); ``None`` when there is none."""
    if failure is None:
        return None
    states = list(getattr(trace, "states", None) or [])
    other = failure.with_
    if other and other != "ego":
        return str(other)
    if not is_standstill(failure.type) or not states:
        return None
    step = failure.step
    step = len(states) - 1 if not isinstance(step, int) else max(0, min(len(states) - 1, step))
    return actor_ahead(states[step])


def extract_behaviour(trace: Any, failure: Optional[Failure]) -> Optional[Behaviour]:
    """The behaviour (module docstring) of ``failure`` in ``trace``; ``None`` without a failure."""
    if failure is None:
        return None
    states = list(getattr(trace, "states", None) or [])
    if not states:
        return UNKNOWN
    frequency = float((getattr(trace, "config", None) or {}).get("policy_frequency", 5))
    steps = max(1, int(round(WINDOW_SECONDS * frequency)))
    step = failure.step
    step = len(states) - 1 if not isinstance(step, int) else max(0, min(len(states) - 1, step))
    if is_contact(failure.type) and step > 0:
        step -= 1  # the state logged at the impact already carries the speed the collision took away
    ego_path = _window(states, "ego", step, steps)
    other = involved_actor(trace, failure)
    if other:
        kinds = getattr(trace, "kinds", None) or {}
        named = other == failure.with_
        actor = str((failure.with_kind if named else None) or kinds.get(other) or "car")
        manoeuvre = _actor_manoeuvre(_window(states, other, step, steps), ego_path)
    else:
        actor, manoeuvre = "none", "none"
    return Behaviour(actor=actor, actor_manoeuvre=manoeuvre, ego_manoeuvre=_ego_manoeuvre(ego_path))


def behaviour_of(record: EpisodeRecord) -> Behaviour:
    """The behaviour of a failed episode record, ``"unknown"`` in each part it does not tell
    (:meth:`Behaviour.complete`; :data:`UNKNOWN` when it has none)."""
    return record.behaviour.complete() if record.behaviour is not None else UNKNOWN
