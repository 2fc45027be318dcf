"""The rule-based driver's path prediction and yielding, on hand-built highway-env roads."""

import math

import numpy as np
import pytest
from highway_env.road.lane import CircularLane, StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.controller import MDPVehicle
from highway_env.vehicle.kinematics import Vehicle

from policies.rule_based import CautiousDriver, _planned_path


def _left_turn_road():
    """A 40 m straight approach, then a 90-degree left arc of radius 10 m (y drawn down)."""
    net = RoadNetwork()
    net.add_lane("a", "b", StraightLane([0, 0], [40, 0]))
    net.add_lane("b", "c", CircularLane([40, -10], 10, math.pi / 2, 0, clockwise=False))
    net.add_lane("a", "d", StraightLane([40, 3.5], [0, 3.5]))  # the opposite direction, next lane
    return Road(network=net)


class _Env:  # the part of an env the driver reads
    def __init__(self, road, ego):
        self.unwrapped = self
        self.config = {"action": {"type": "DiscreteMetaAction"}}
        self.road, self.vehicle, self.steps = road, ego, 1


def _ego(road, x=20.0, speed=8.0):
    ego = MDPVehicle(road, road.network.get_lane(("a", "b", 0)).position(x, 0), heading=0.0, speed=speed)
    ego.route = [("a", "b", 0), ("b", "c", 0)]
    road.vehicles.append(ego)
    return ego


def test_planned_path_follows_the_route_through_the_turn():
    road = _left_turn_road()
    ego = _ego(road)
    times = np.arange(0.0, 6.01, 0.5)
    path = _planned_path(ego, times, speed=8.0)
    assert np.allclose(path[0], [20.0, 0.0])
    assert np.allclose(path[2], [28.0, 0.0])  # 8 m along the approach after 1 s
    # 48 m along: 20 m of approach, the 15.7 m arc, then straight on along the arc's end heading (-y)
    assert path[-1] == pytest.approx([50.0, -10.0 - (48.0 - 20.0 - 5 * math.pi)], abs=0.05)
    assert ego.route == [("a", "b", 0), ("b", "c", 0)]  # predicting did not consume the route


def test_yields_to_a_car_crossing_the_planned_turn_but_not_to_traffic_in_the_next_lane():
    road = _left_turn_road()
    ego = _ego(road, x=30.0)
    driver = CautiousDriver(_Env(road, ego), cruise_speed=8.0)
    passing = Vehicle(road, [45.0, 3.5], heading=math.pi, speed=10.0)  # oncoming, stays in its lane
    road.vehicles.append(passing)
    assert not driver._path_conflict(ego, road.vehicles)
    assert driver.act() != 4  # SLOWER
    # a car from the side that reaches the ego's arc when the ego does, 2.5 s from now
    crossing = Vehicle(road, [48.4, 15.4], heading=-math.pi / 2, speed=8.0)
    road.vehicles.append(crossing)
    assert driver._path_conflict(ego, road.vehicles)
    assert driver.act() == 4
