"""A Kinematics observation computed with NumPy instead of pandas, and the ego's route features.

highway-env's ``KinematicObservation`` builds several pandas DataFrames on every
step; with a handful of vehicles that costs more than the physics. This class
produces the same array (same rows, order, normalisation, clipping, padding and
dtype; ``tests/test_fast_paths.py`` compares both on live scenes) without pandas.

It also computes two features highway-env does not have, :data:`ROUTE_FEATURES`, which tell a policy where
its own vehicle is meant to go (the scenario's route for the ego, ``with route [...]`` in the script):

- ``route_turn``: the heading change from the ego's heading to the heading at the end of its route, wrapped to
  [-180°, 180°) and divided by 180° (in [-1, 1]; positive to the left, negative to the right, 0 straight on).
  Before a left turn at a junction it is about +0.5 and it falls to about 0 once the ego has turned.
- ``route_bearing``: the direction from the ego to the end of its route, relative to the ego's heading, in the
  same units (positive to the left).

Only the ego's row carries them: every other vehicle's row has 0 there (its route is the script's, which the
ego could not know). A vehicle without a route (an ego with ``ContinuousAction``, or after its route has ended)
has 0 in both. Without a ``with route`` in the script highway-env gives the ego a route of its starting lane
only, so the features follow that lane's end, then are 0.
"""

from __future__ import annotations

import math
from typing import Dict

import numpy as np
from highway_env import utils
from highway_env.envs.common.observation import KinematicObservation
from highway_env.road.lane import AbstractLane
from highway_env.vehicle.kinematics import Vehicle

__all__ = ["FastKinematicObservation", "KINEMATIC_FEATURES", "ROUTE_FEATURES", "route_features"]

ROUTE_FEATURES = ("route_turn", "route_bearing")
"""Kinematics features of the ego's route (module docstring); only the ego's row is non-zero."""

KINEMATIC_FEATURES = ("presence", "x", "y", "vx", "vy", "heading", "cos_h", "sin_h", "cos_d", "sin_d",
                      "long_off", "lat_off", "ang_off") + ROUTE_FEATURES
"""Every feature name a ``Kinematics`` observation of DV2S-v0 takes: highway-env's (``Vehicle.to_dict``) and
:data:`ROUTE_FEATURES`."""

_NO_ROUTE = {name: 0.0 for name in ROUTE_FEATURES}


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def route_features(vehicle) -> Dict[str, float]:
    """:data:`ROUTE_FEATURES` of ``vehicle`` (highway-env frame: its heading grows clockwise on screen, so the
    sign is flipped to make left positive)."""
    route = getattr(vehicle, "route", None)
    road = getattr(vehicle, "road", None)
    if not route or road is None:
        return dict(_NO_ROUTE)
    last = route[-1]
    if last[-1] is None:
        last = (*last[:-1], 0)
    try:
        lane = road.network.get_lane(last)
    except (KeyError, IndexError):
        return dict(_NO_ROUTE)
    end = np.asarray(lane.position(lane.length, 0.0), dtype=float)
    heading = float(vehicle.heading)
    turn = -_wrap(float(lane.heading_at(lane.length)) - heading) / math.pi
    offset = end - np.asarray(vehicle.position, dtype=float)
    bearing = 0.0
    if float(np.hypot(*offset)) > 1e-6:
        bearing = -_wrap(math.atan2(offset[1], offset[0]) - heading) / math.pi
    return {"route_turn": float(turn), "route_bearing": float(bearing)}


class FastKinematicObservation(KinematicObservation):
    """Drop-in replacement for highway-env's ``KinematicObservation`` (with :data:`ROUTE_FEATURES`)."""

    def _ranges(self):
        if not self.features_range:
            side_lanes = self.env.road.network.all_side_lanes(self.observer_vehicle.lane_index)
            self.features_range = {
                "x": [-5.0 * Vehicle.MAX_SPEED, 5.0 * Vehicle.MAX_SPEED],
                "y": [-AbstractLane.DEFAULT_WIDTH * len(side_lanes), AbstractLane.DEFAULT_WIDTH * len(side_lanes)],
                "vx": [-2 * Vehicle.MAX_SPEED, 2 * Vehicle.MAX_SPEED],
                "vy": [-2 * Vehicle.MAX_SPEED, 2 * Vehicle.MAX_SPEED],
            }
        return self.features_range

    def observe(self) -> np.ndarray:
        if not self.env.road:
            return np.zeros(self.space().shape)
        ego = self.observer_vehicle
        records = [ego.to_dict()]
        route = any(f in ROUTE_FEATURES for f in self.features)
        if route:
            records[0].update(route_features(ego))
        close = self.env.road.close_objects_to(
            ego,
            self.env.PERCEPTION_DISTANCE,
            count=self.vehicles_count - 1,
            see_behind=self.see_behind,
            sort=self.order == "sorted",
            vehicles_only=not self.include_obstacles,
        )
        if close:
            origin = ego if not self.absolute else None
            records += [v.to_dict(origin, observe_intentions=self.observe_intentions)
                        for v in close[-self.vehicles_count + 1:]]
            if route:  # another vehicle's route is its script's: never shown
                for record in records[1:]:
                    record.update(_NO_ROUTE)
        table = np.array([[r.get(f, np.nan) for f in self.features] for r in records], dtype=float)
        if self.normalize:
            for feature, (low, high) in self._ranges().items():
                if feature in self.features:
                    j = self.features.index(feature)
                    column = utils.lmap(table[:, j], [low, high], [-1, 1])
                    table[:, j] = np.clip(column, -1, 1) if self.clip else column
        if table.shape[0] < self.vehicles_count:
            table = np.vstack([table, np.zeros((self.vehicles_count - table.shape[0], len(self.features)))])
        if self.order == "shuffled":
            self.env.np_random.shuffle(table[1:])
        dtype = self.__dict__.get("_dtype")
        if dtype is None:  # building the space (a gymnasium Box) on every step cost more than the table
            dtype = self._dtype = self.space().dtype
        return table.astype(dtype)
