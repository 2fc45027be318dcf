"""Python helpers for ``model.scenic``: map-name resolution and missing actions.

Kept in Python so they can be tested without compiling a scenario.
"""

from __future__ import annotations

import math

from scenic.core.simulators import Action
from scenic.core.vectors import Vector
from scenic.domains.driving.actions import WalkingAction

__all__ = ["resolve_map_parameter", "WalkTowardsAction", "install_driving_behavior_support"]


class MissingMapError(ValueError):
    """The scenario names no map."""


def resolve_map_parameter() -> None:
    """Turn a short map name in ``param map`` into the path of a shipped map.

    Must run before the driving domain is imported, because the driving model
    loads ``globalParameters.map`` at import time. Paths are left as they are.
    """
    import scenic.syntax.veneer as veneer
    from scenario_bank.maps import resolve_map

    params = veneer._globalParameters
    if "map" not in params:
        raise MissingMapError(
            "this scenario sets no map: add `param map = 'highway_straight'` (a shipped map name) "
            "or `param map = localPath('my_map.xodr')` before the `model` line, "
            "or pass config={'map': ...} to the environment"
        )
    value = params["map"]
    if isinstance(value, str):
        params["map"] = str(resolve_map(value))


class WalkTowardsAction(WalkingAction):
    """Walk toward a point (or along a direction vector) at the current speed.

    The driving domain's ``WalkForwardBehavior`` uses this action but only the
    CARLA interface defines it; this is the highway-env version.
    """

    def __init__(self, goal_position) -> None:
        self.goal_position = goal_position

    def applyTo(self, obj, sim) -> None:
        goal = Vector(*self.goal_position[:2]) if not isinstance(self.goal_position, Vector) else self.goal_position
        offset = goal - obj.position
        # A unit-length goal is the direction itself (as WalkForwardBehavior passes it).
        direction = goal if abs(goal.norm() - 1.0) < 1e-6 else offset
        if direction.norm() < 1e-9:
            return
        heading = math.atan2(-direction[0], direction[1])
        obj.setWalkingDirection(heading)


def install_driving_behavior_support() -> None:
    """Give the driving domain's behaviour library the names it expects from a simulator."""
    import sys

    behaviors = sys.modules.get("scenic.domains.driving.behaviors")
    if behaviors is not None and not hasattr(behaviors, "WalkTowardsAction"):
        behaviors.WalkTowardsAction = WalkTowardsAction


__all__.append("MissingMapError")
_ = Action  # re-exported type for model authors
