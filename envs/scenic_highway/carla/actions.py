"""Python side of the CARLA-model façade: blueprint kinds, CARLA actions, traffic-light helpers.

Scripts written against ``scenic.simulators.carla.model`` compile against
``envs/scenic_highway/carla/model.scenic``, which takes its names from here. Each
CARLA action is either emulated in highway-env's 2D world, accepted as a no-op with
an :class:`envs.errors.ForeignConstructWarning` (it only changes a look or a
drivetrain detail), or refused with an :class:`envs.errors.UnsupportedConstructError`
naming it. Nothing here imports ``carla``.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any, Optional, Tuple

import scenic.syntax.veneer as veneer
from scenic.core.simulators import Action
from scenic.domains.driving.actions import SetSpeedAction  # noqa: F401  (re-exported for scripts)

from envs.errors import ForeignConstructWarning, UnsupportedConstructError

__all__ = [
    "TRAFFIC_LIGHTS_WARNING",
    "warn_no_traffic_lights",
    "SetAutopilotAction",
    "SetWalkAction",
    "SetGearAction",
    "SetManualGearShiftAction",
    "SetManualFirstGearShiftAction",
    "SetVehicleLightStateAction",
    "SetTrafficLightAction",
    "SetJumpAction",
    "SetAngularVelocityAction",
    "SetTransformAction",
    "TrackWaypointsAction",
    "freezeTrafficLights",
    "unfreezeTrafficLights",
    "setAllIntersectionTrafficLightsStatus",
    "setTrafficLightStatus",
    "getTrafficLightStatus",
    "withinDistanceToRedYellowTrafficLight",
    "withinDistanceToTrafficLight",
    "getClosestTrafficLightStatus",
    "setClosestTrafficLightStatus",
]

TRAFFIC_LIGHTS_WARNING = (
    "traffic lights are not simulated in DV2S-v0 (highway-env has none): the CARLA traffic-light "
    "helpers answer as if there were no light nearby and SetTrafficLightAction does nothing"
)
_warned_scripts: set = set()


def warn_no_traffic_lights() -> None:
    """Warn once per running scenario (or once per compile outside a simulation) that lights are absent."""
    key: Optional[int]
    try:
        simulation = veneer.currentSimulation  # the running one: read when called, never bound at import
        key = id(simulation.scene) if simulation is not None else None
    except Exception:  # pragma: no cover - defensive
        key = None
    if key in _warned_scripts:
        return
    _warned_scripts.add(key)
    warnings.warn(TRAFFIC_LIGHTS_WARNING, ForeignConstructWarning, stacklevel=3)


def _dropped(construct: str, why: str) -> None:
    warnings.warn(f"`{construct}` is ignored in DV2S-v0: {why}", ForeignConstructWarning, stacklevel=3)


def _refuse(construct: str, why: str) -> UnsupportedConstructError:
    path, line = _script_location()
    where = f"{path}, line {line}: " if path else ""
    return UnsupportedConstructError(
        f"{where}unsupported construct `{construct}`: {why} (Scenic's CARLA interface, scenic.simulators.carla); "
        "it has no 2D highway-env equivalent.",
        path=path,
        line=line,
    )


def _script_location() -> Tuple[Optional[str], Optional[int]]:
    """File and line of the innermost user script frame (a ``.scenic`` file outside this package)."""
    frame = sys._getframe(1)
    own = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    while frame is not None:
        name = frame.f_code.co_filename
        if not os.path.abspath(name).startswith(own) and (name.endswith(".scenic") or name.startswith("<")) \
                and "site-packages" not in name:
            return name, frame.f_lineno
        frame = frame.f_back
    return None, None


class _NoOpAction(Action):
    def applyTo(self, obj, sim) -> None:  # noqa: D102 - nothing to do
        return None


class _RefusedAction(Action):
    """An action whose constructor refuses it; ``applyTo`` is never reached."""

    def applyTo(self, obj, sim) -> None:  # pragma: no cover - __init__ raises first
        raise NotImplementedError


class SetAutopilotAction(_RefusedAction):
    """CARLA's autopilot switch. Taken directly it cannot be emulated (the autopilot is a
    persistent controller, not a per-step action); ``AutopilotBehavior`` is emulated instead."""

    def __init__(self, enabled: bool, **kwargs) -> None:
        raise _refuse(
            "SetAutopilotAction",
            "it hands the vehicle to CARLA's Traffic Manager; use `AutopilotBehavior` (emulated by lane "
            "following) or `FollowLaneBehavior` instead",
        )


class SetWalkAction(Action):
    """CARLA's AI walker switch, emulated: the pedestrian walks ahead at ``maxSpeed`` (stops when disabled)."""

    def __init__(self, enabled: bool, maxSpeed: float = 1.4) -> None:
        self.enabled = bool(enabled)
        self.maxSpeed = float(maxSpeed)

    def applyTo(self, obj, sim) -> None:  # noqa: D102
        obj.setWalkingDirection(obj.heading)
        obj.setWalkingSpeed(self.maxSpeed if self.enabled else 0.0)


class SetGearAction(_NoOpAction):
    """A manual gear choice: the kinematic model has no drivetrain, so it is a no-op with a warning."""

    def __init__(self, gear: int) -> None:
        _dropped("SetGearAction", "highway-env's kinematic vehicles have no gearbox")


class SetManualGearShiftAction(_NoOpAction):
    """Manual gear shifting on or off: a no-op with a warning (no gearbox)."""

    def __init__(self, manualGearShift: bool) -> None:
        _dropped("SetManualGearShiftAction", "highway-env's kinematic vehicles have no gearbox")


class SetManualFirstGearShiftAction(_NoOpAction):
    """CARLA's first-gear helper: a no-op with a warning (no gearbox)."""

    def __init__(self) -> None:
        _dropped("SetManualFirstGearShiftAction", "highway-env's kinematic vehicles have no gearbox")


class SetVehicleLightStateAction(_NoOpAction):
    """Vehicle lights are cosmetic; not drawn, so a no-op with a warning."""

    def __init__(self, vehicleLightState: Any) -> None:
        _dropped("SetVehicleLightStateAction", "vehicle lights are not drawn")


class SetTrafficLightAction(_NoOpAction):
    """Set the nearest traffic light: there are none, so a no-op (with the traffic-light warning)."""

    def __init__(self, color: Any, distance: float = 100, group: bool = False) -> None:
        warn_no_traffic_lights()


class SetJumpAction(_RefusedAction):
    """A walker jump: refused (there is no vertical dimension in 2D)."""

    def __init__(self, jump: bool) -> None:
        raise _refuse("SetJumpAction", "a pedestrian jump needs a vertical dimension")


class SetAngularVelocityAction(_RefusedAction):
    """Refused: highway-env vehicles turn by steering, their yaw rate cannot be set."""

    def __init__(self, angularVel: Any) -> None:
        raise _refuse("SetAngularVelocityAction", "it sets a CARLA actor's yaw rate directly")


class SetTransformAction(Action):
    """Teleport to a position and heading, emulated with the simulator's position setter."""

    def __init__(self, pos: Any, heading: float) -> None:
        self.pos = pos
        self.heading = heading

    def applyTo(self, obj, sim) -> None:  # noqa: D102
        sim.set_actor_position(obj, self.pos)


class TrackWaypointsAction(_RefusedAction):
    """CARLA's waypoint tracker (an MPC on CARLA's vehicle physics): refused."""

    def __init__(self, waypoints: Any, cruising_speed: float = 10.0) -> None:
        raise _refuse(
            "TrackWaypointsAction",
            "it tracks waypoints with a controller tuned to CARLA's vehicle physics; use "
            "FollowTrajectoryBehavior or FollowLaneBehavior",
        )


# --- traffic-light helpers of scenic.simulators.carla.model: "there are no lights here" ---

def freezeTrafficLights() -> None:
    """No lights to freeze (warns once)."""
    warn_no_traffic_lights()


def unfreezeTrafficLights() -> None:
    """No lights to unfreeze (warns once)."""
    warn_no_traffic_lights()


def setAllIntersectionTrafficLightsStatus(intersection: Any, color: Any) -> None:
    """No lights at any intersection (warns once)."""
    warn_no_traffic_lights()


def setTrafficLightStatus(signal: Any, color: Any) -> None:
    """No light to set (warns once)."""
    warn_no_traffic_lights()


def getTrafficLightStatus(signal: Any) -> Optional[str]:
    """``None``: no light (warns once)."""
    warn_no_traffic_lights()
    return None


def withinDistanceToRedYellowTrafficLight(vehicle: Any, thresholdDistance: float) -> bool:
    """``False``: no red or yellow light is ever near (warns once)."""
    warn_no_traffic_lights()
    return False


def withinDistanceToTrafficLight(vehicle: Any, thresholdDistance: float) -> bool:
    """``False``: no light is ever near (warns once)."""
    warn_no_traffic_lights()
    return False


def getClosestTrafficLightStatus(vehicle: Any, distance: float = 100) -> Optional[str]:
    """``None``: no light within any distance (warns once)."""
    warn_no_traffic_lights()
    return None


def setClosestTrafficLightStatus(vehicle: Any, color: Any, distance: float = 100) -> None:
    """No light to set (warns once)."""
    warn_no_traffic_lights()
