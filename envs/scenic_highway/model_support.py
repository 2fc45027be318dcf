"""Python helpers for ``model.scenic``: map-name resolution, fixes to the driving
domain's behaviour library (missing and buggy actions, centerline seams) and
clear errors for CARLA-only object attributes.

Kept in Python so they can be tested without compiling a scenario.
"""

from __future__ import annotations

import math
import os
import sys

import scenic.syntax.veneer as veneer
from scenic.core.regions import PolylineRegion
from scenic.core.simulators import Action
from scenic.core.vectors import Vector
from scenic.domains.driving import actions as _driving_actions
from scenic.domains.driving.actions import WalkingAction

from scenario_bank.errors import DV2SError
from envs.errors import UnsupportedConstructError
from scenario_bank.map_cache import install_network_cache
from scenario_bank.maps import resolve_map

__all__ = [
    "resolve_map_parameter",
    "remove_backward_seams",
    "NoCarlaActor",
    "WalkTowardsAction",
    "RegulatedControlAction",
    "install_driving_behavior_support", "MissingMapError"]


class MissingMapError(DV2SError, ValueError):
    """The scenario names no map."""


def resolve_map_parameter() -> None:
    """Turn a short map name in ``param map`` into the path of a shipped map.

    Must run before the driving domain is imported, because the driving model
    loads ``globalParameters.map`` at import time. Paths (``localPath(...)``) become
    plain strings: a ``pathlib.Path`` left in ``globalParameters`` would hand the
    script file-system methods (``globalParameters.map.replace(...)`` moves the file).
    """
    install_network_cache()  # the driving model's Network.fromFile caches outside the package

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
    elif isinstance(value, os.PathLike):
        params["map"] = os.fspath(value)


def remove_backward_seams(network) -> int:
    """Drop the backward-pointing seam segments of every lane centerline; returns how many.

    Scenic chains the centerlines of consecutive OpenDRIVE geometries and leaves
    centimetre-long segments at some seams that point *against* the lane (28 of
    Town01's 124 lanes have them). The driving behaviours steer on
    ``signedDistanceTo`` the nearest centerline segment, whose sign flips on such
    a segment: a car passing one is told it is on the wrong side of its path and
    swerves. Removing these vertices moves the centerline by a few centimetres.
    """
    removed = 0
    for lane in network.lanes:
        points = [tuple(p[:2]) for p in lane.centerline.points]
        cleaned = _without_backward_segments(points)
        if len(cleaned) != len(points):
            removed += len(points) - len(cleaned)
            lane.centerline = PolylineRegion(cleaned)
    return removed


def _without_backward_segments(points, window: int = 3):
    points = list(points)
    changed = True
    while changed and len(points) > 2:
        changed = False
        for i in range(len(points) - 1):
            lo, hi = max(0, i - window), min(len(points) - 1, i + 1 + window)
            chord = (points[hi][0] - points[lo][0], points[hi][1] - points[lo][1])
            seg = (points[i + 1][0] - points[i][0], points[i + 1][1] - points[i][1])
            if seg[0] * chord[0] + seg[1] * chord[1] < 0:
                # drop the vertex that is not a polyline end
                del points[i + 1 if i + 1 < len(points) - 1 else i]
                changed = True
                break
    return points


class WalkTowardsAction(WalkingAction):
    """Walk toward a point at the current speed.

    The driving domain's ``WalkForwardBehavior`` uses this action but only the
    CARLA interface of older Scenic versions defined it; this is the highway-env
    version. ``WalkForwardBehavior`` means to walk toward a random vertex of the
    pedestrian's sidewalk centerline but passes that point *normalised* (its
    position vector scaled to length 1). A unit-length goal is therefore matched
    against the vertices of the sidewalk the pedestrian is on, and the pedestrian
    walks toward the vertex it came from; a unit vector matching no vertex is
    taken as a walking direction.
    """

    def __init__(self, goal_position) -> None:
        self.goal_position = goal_position

    def applyTo(self, obj, sim) -> None:
        goal = self.goal_position
        goal = goal if isinstance(goal, Vector) else Vector(*goal[:2])
        if abs(goal.norm() - 1.0) < 1e-6:
            vertex = _sidewalk_vertex_along(obj, sim, goal)
            direction = goal if vertex is None else vertex - obj.position
        else:
            direction = goal - obj.position
        if math.hypot(direction[0], direction[1]) < 1e-9:
            return
        heading = math.atan2(-direction[0], direction[1])
        obj.setWalkingDirection(heading)


def _sidewalk_vertex_along(obj, sim, unit: Vector):
    """The vertex of ``obj``'s sidewalk centerline whose direction from the origin is ``unit``."""
    network = getattr(getattr(sim.scene, "workspace", None), "network", None)
    if network is None:
        return None
    try:
        sidewalk = network.sidewalkAt(obj.position)
    except Exception:  # pragma: no cover - defensive: no sidewalk lookup on this network
        return None
    if sidewalk is None:
        return None
    best, best_error = None, 1e-6
    for point in sidewalk.centerline.points:
        vertex = Vector(point[0], point[1])
        norm = vertex.norm()
        if norm < 1e-9:
            continue
        error = math.hypot(vertex[0] / norm - unit[0], vertex[1] / norm - unit[1])
        if error <= best_error:
            best, best_error = vertex, error
    return best


class RegulatedControlAction(_driving_actions.RegulatedControlAction):
    """``RegulatedControlAction`` that really brakes, with a per-second steering rate.

    Two fixes of Scenic 3.1's version, which the lane following, turning and lane
    changing behaviours use:

    * it zeroes ``throttle`` before deriving ``brake`` from it, so the brake is
      always 0 and a car can only coast. In CARLA or MetaDrive drag still slows
      it down; highway-env's kinematic model has none, so a car overshooting its
      target speed (or slowing for a turn in ``FollowLaneBehavior``) would keep
      its speed forever. Here a negative signal brakes with
      ``min(-throttle, max_brake)``, as documented.
    * it lets the steering change by at most 0.1 per action, tuned for CARLA's
      0.1 s time step; at this environment's default 0.2 s step that halves the
      steering rate and cars cannot follow a town corner. The limit is applied
      as 0.1 per 0.1 s of the running simulation's time step.
    """

    def __init__(
        self,
        throttle: float,
        steer: float,
        past_steer: float,
        max_throttle: float = 0.5,
        max_brake: float = 0.5,
        max_steer: float = 0.8,
    ) -> None:
        super().__init__(throttle, steer, past_steer, max_throttle, max_brake, max_steer)
        if throttle < 0:
            self.brake = min(-throttle, max_brake)
        self._steer_request = (steer, past_steer, max_steer)

    def applyTo(self, obj, sim) -> None:
        steer, past_steer, max_steer = self._steer_request
        timestep = getattr(sim, "timestep", None) or STEERING_RATE_TIMESTEP
        step = 0.1 * timestep / STEERING_RATE_TIMESTEP
        steer = min(max(steer, past_steer - step), past_steer + step)
        self.steer = max(-max_steer, min(max_steer, steer))
        super().applyTo(obj, sim)


STEERING_RATE_TIMESTEP = 0.1
"""Time step [s] for which Scenic's steering regulation (0.1 per action) was tuned."""


class NoCarlaActor:
    """Mixin for the model's classes: CARLA-only object attributes fail clearly.

    Scripts written for CARLA may read ``obj.carlaActor`` (the CARLA actor behind
    a Scenic object) in behaviours; without this they would fail with a bare
    ``AttributeError`` mid-episode.
    """

    @property
    def carlaActor(self):
        raise UnsupportedConstructError(
            "unsupported construct `carlaActor`: it is the CARLA actor of an object in "
            "Scenic's CARLA interface (scenic.simulators.carla) and has no highway-env "
            "equivalent. Use driving-domain properties (position, heading, velocity, speed, "
            "lane...) and actions instead."
        )


def install_driving_behavior_support() -> None:
    """Give the driving domain's behaviour library the names it expects from a simulator.

    Adds ``WalkTowardsAction`` (used by ``WalkForwardBehavior``) and replaces
    ``RegulatedControlAction`` (used by the lane-following, turning and lane
    changing behaviours) with the braking fix above.
    """
    behaviors = sys.modules.get("scenic.domains.driving.behaviors")
    if behaviors is None:
        return
    if not hasattr(behaviors, "WalkTowardsAction"):
        behaviors.WalkTowardsAction = WalkTowardsAction
    behaviors.RegulatedControlAction = RegulatedControlAction


__all__.append("MissingMapError")
_ = Action  # re-exported type for model authors


class NoMetaDriveActor:
    """Mixin for the MetaDrive façade's classes: ``obj.metaDriveActor`` fails clearly."""

    @property
    def metaDriveActor(self):
        raise UnsupportedConstructError(
            "unsupported construct `metaDriveActor`: it is the MetaDrive object behind a Scenic object in "
            "Scenic's MetaDrive interface (scenic.simulators.metadrive) and has no highway-env equivalent. "
            "Use driving-domain properties (position, heading, velocity, speed, lane...) and actions instead."
        )


__all__.append("NoMetaDriveActor")
