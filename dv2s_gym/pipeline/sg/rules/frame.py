"""What a script has to show: the frame of actors (kinds, counts, actions, relations, roles) and the result."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from dv2s_gym.pipeline.sg.rules.roles import Role
from scenario_bank.elements import ActorKind, Elements

__all__ = ["VEHICLES", "CLASS", "KIND_SPEEDS", "ActorFrame", "ScenarioFrame", "SGResult"]

VEHICLES = (ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE, ActorKind.BICYCLE)
CLASS = {ActorKind.CAR: "Car", ActorKind.TRUCK: "Truck", ActorKind.BUS: "Bus", ActorKind.MOTORCYCLE: "Motorcycle",
         ActorKind.BICYCLE: "Bicycle", ActorKind.PEDESTRIAN: "Pedestrian", ActorKind.OBSTACLE: "Obstacle"}
KIND_SPEEDS = {ActorKind.BICYCLE: "Range(4, 6)"}
"""Cruise speed (m/s) of a kind slower than the road's traffic; it replaces the road's speed range."""


@dataclass
class ActorFrame:
    """One actor (or a group of same-type actors) the script places."""

    name: str
    kind: str
    count: int = 1
    actions: List[str] = field(default_factory=list)
    details: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    relations: List[str] = field(default_factory=list)
    lane: Optional[str] = None
    sudden: bool = False
    state_stop: bool = False
    cross_dirs: List[Tuple[str, int]] = field(default_factory=list)
    role: Optional[Role] = None
    """The role on a straight road, once the straight-road composer assigns it (None at a junction)."""
    side: int = 0
    parked: bool = False

    def has(self, action: str) -> bool:
        return action in self.actions


@dataclass
class ScenarioFrame:
    """What the script has to show: road/map, the ego and the other actors."""

    description: str
    road: Optional[str]
    map: str
    ego: ActorFrame
    actors: List[ActorFrame]
    ego_mentioned: bool
    weather: str = "any"


@dataclass
class SGResult:
    """A generated script with its frame, what could not be placed and what it is meant to show."""

    script: str
    frame: ScenarioFrame
    warnings: List[str]
    elements: Elements
    backend: str = "rules"
    context_hash: str = ""
