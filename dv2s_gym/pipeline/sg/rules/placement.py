"""Where a driving vehicle on a straight road starts and how it moves, and the Scenic lines for its group."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, List, Optional

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import ActorKind

__all__ = ["Placement", "Placer", "driving"]


@dataclass
class Placement:
    """A driving vehicle's start (``position``, a ``...pointAlongBy(...)`` expression), start ``speed``, ``behavior``
    and what the script shows of it (``relations`` to the ego, ``actions``)."""

    speed: str
    relations: List[str]
    actions: List[str]
    position: Optional[str] = None
    behavior: Optional[str] = None

    @classmethod
    def start(cls, actor: ActorFrame, speed: str) -> "Placement":
        """Driving at ``speed``, showing what the actor is described with."""
        return cls(speed=speed, relations=list(actor.relations), actions=list(actor.actions))


Placer = Callable[[Script, ActorFrame, LaneContext, Placement], None]
"""Fills in a :class:`Placement` for a role (``speed`` is the speed the actor drives at unless the role says)."""


def driving(place: Placer) -> Callable[[Script, ActorFrame, LaneContext, str], None]:
    """A spawn function for a role whose vehicles drive: ``place`` fills in the placement, which is written out."""
    def spawn(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
        p = Placement.start(actor, speed)
        place(s, actor, ctx, p)
        _write(s, actor, p)
    return spawn


def _write(s: Script, actor: ActorFrame, p: Placement) -> None:
    n = actor.name
    lines: List[str] = []
    behavior, position = p.behavior, p.position
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        pos = position
        if i:
            # further members of a group: the same manoeuvre, one vehicle length and a gap further on
            step = (18 if actor.kind == ActorKind.TRUCK else 12) * i
            sign = "+" if actor.role in (Role.LEAD, Role.SLOW_LEAD) else "-"
            pos = re.sub(r"pointAlongBy\((.*)\)$", lambda m: f"pointAlongBy({m.group(1)} {sign} {step})", position)
        start_speed = "0" if behavior and behavior.startswith("HoldStill") else p.speed
        if actor.has("accelerate") and behavior and not behavior.startswith(("SpeedUpLater", "MergeFromRamp")):
            start_speed = f"{p.speed} - Range(5, 7)"  # it speeds up to its target speed
        lines += [f"{var} = new {CLASS[actor.kind]} at {pos},",
                  f"    with speed {start_speed},",
                  f"    with behavior {behavior}"]
    s.spawn += lines
    s.show(actor.kind, list(p.actions), [r for r in dict.fromkeys(p.relations)], actor.count)
