"""A Kinematics observation computed with NumPy instead of pandas.

highway-env's ``KinematicObservation`` builds several pandas DataFrames on every
step; with a handful of vehicles that costs more than the physics. This class
produces the same array (same rows, order, normalisation, clipping, padding and
dtype; ``tests/test_fast_paths.py`` compares both on live scenes) without pandas.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils
from highway_env.envs.common.observation import KinematicObservation
from highway_env.road.lane import AbstractLane
from highway_env.vehicle.kinematics import Vehicle

__all__ = ["FastKinematicObservation"]


class FastKinematicObservation(KinematicObservation):
    """Drop-in replacement for highway-env's ``KinematicObservation``."""

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
