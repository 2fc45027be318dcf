"""Strict trace semantics: go_straight, keep_lane, the ego's own actions, collision types.

Synthetic traces on the shipped maps (highway-env frame: heading 0 drives +x).
urban_crossroads: the eastbound lane is y = 1.75, the junction spans x, y in [-12, 12].
urban_two_way: eastbound y = 1.75, westbound y = -1.75. highway_straight: lanes at y = 1.75, 5.25, 8.75, 12.25.
"""

import math

import pytest

from dv2s_gym.pipeline.semantics.trace import collision_type, elements_from_trace
from envs.trace import EpisodeTrace

DT = 0.2


def _trace(states, events=(), kinds=None, map_name="highway_straight"):
    return EpisodeTrace(scenario="t", source="", seed=0, scene_seed=0, params={"map": f"/x/{map_name}.xodr"},
                        config={"policy_frequency": 5}, states=list(states), events=list(events), kinds=kinds or {})


def _drive(x0, speed, steps=50, y=1.75, heading=0.0, stop_at=None):
    """Positions of a vehicle driving along +x (or -x for heading pi), optionally stopping at ``stop_at``."""
    rows, x, v = [], x0, speed
    sign = 1.0 if abs(heading) < 1 else -1.0
    for _ in range(steps):
        rows.append([x, y, heading, v])
        if stop_at is not None and sign * (stop_at - x) < max(v * DT, 1e-9) * 4:
            v = max(0.0, v - 2.0)
        x += sign * v * DT
    return rows


def _actions(elements, kind):
    return {a for k, a in elements.actions if k == kind}


# ------------------------------------------------------------------------------------------- go_straight

def test_ego_driving_through_the_junction_goes_straight():
    ego = _drive(-40.0, 8.0)  # 80 m in 10 s: from x=-40 through the junction to x=+40
    elements = elements_from_trace(_trace([{"ego": e} for e in ego], map_name="urban_crossroads"))
    assert elements.road == "intersection"
    assert "go_straight" in _actions(elements, "ego")


def test_ego_stopping_before_the_junction_does_not_go_straight():
    ego = _drive(-60.0, 8.0, stop_at=-32.0)  # stops about 20 m before the junction edge (x = -12)
    assert ego[-1][0] < -25.0 and ego[-1][3] == 0.0
    elements = elements_from_trace(_trace([{"ego": e} for e in ego], map_name="urban_crossroads"))
    assert "go_straight" not in _actions(elements, "ego")
    assert "stop" in _actions(elements, "ego")


def test_ego_stopping_inside_the_junction_does_not_go_straight():
    ego = _drive(-40.0, 8.0, stop_at=2.0)
    assert -12.0 < ego[-1][0] < 12.0
    elements = elements_from_trace(_trace([{"ego": e} for e in ego], map_name="urban_crossroads"))
    assert "go_straight" not in _actions(elements, "ego")


def test_other_car_crossing_the_junction_goes_straight_and_a_waiting_one_does_not():
    ego = _drive(-60.0, 4.0, stop_at=-20.0)
    # A car on the crossing road, driving -y (heading -pi/2) at x = 1.75 through the junction ...
    crossing = [[1.75, 40.0 - 8.0 * DT * k, -math.pi / 2, 8.0] for k in range(50)]
    # ... and one that waits at its stop line, 20 m up the road.
    waiting = [[1.75, 32.0, -math.pi / 2, 0.0] for _ in range(50)]
    for car, expected in ((crossing, True), (waiting, False)):
        states = [{"ego": e, "Car1": c} for e, c in zip(ego, car)]
        elements = elements_from_trace(_trace(states, map_name="urban_crossroads"))
        assert ("go_straight" in _actions(elements, "car")) is expected


def test_no_go_straight_on_a_road_without_a_junction():
    ego = _drive(0.0, 8.0)
    elements = elements_from_trace(_trace([{"ego": e} for e in ego], map_name="urban_two_way"))
    assert "go_straight" not in _actions(elements, "ego")


# ------------------------------------------------------------------------------------------- keep_lane

def test_keep_lane_needs_a_meaningful_distance_in_the_lane():
    moving = _drive(0.0, 10.0)                   # 100 m in its lane
    parked = [[30.0, 1.75, 0.0, 0.0]] * 50       # never moves
    creeping = _drive(40.0, 1.5)                 # 15 m: less than the 20 m it takes
    states = [{"ego": e} for e in moving]
    assert "keep_lane" in _actions(elements_from_trace(_trace(states)), "ego")
    for car in (parked, creeping):
        states = [{"ego": e, "Car1": c} for e, c in zip(moving, car)]
        assert "keep_lane" not in _actions(elements_from_trace(_trace(states)), "car")


def test_a_stopped_ego_does_not_keep_its_lane():
    ego = _drive(0.0, 8.0, stop_at=10.0)
    elements = elements_from_trace(_trace([{"ego": e} for e in ego]))
    assert "keep_lane" not in _actions(elements, "ego") and "stop" in _actions(elements, "ego")


def test_a_car_sliding_into_the_next_lane_without_an_event_does_not_keep_its_lane():
    ego = _drive(0.0, 10.0)
    car = [[20.0 + 10.0 * DT * k, 5.25 - min(3.5, 0.2 * k), 0.0, 10.0] for k in range(50)]
    states = [{"ego": e, "Car1": c} for e, c in zip(ego, car)]
    assert "keep_lane" not in _actions(elements_from_trace(_trace(states)), "car")


def test_a_car_with_a_lane_change_event_does_not_keep_its_lane():
    ego = _drive(0.0, 10.0)
    car = [[30.0 + 12.0 * DT * k, 5.25 if k < 10 else 8.75, 0.0, 12.0] for k in range(50)]
    events = [{"time": 2.0, "kind": "lane_change", "actors": ["Car1"], "direction": "right"}]
    elements = elements_from_trace(_trace([{"ego": e, "Car1": c} for e, c in zip(ego, car)], events))
    assert "keep_lane" not in _actions(elements, "car") and "lane_change_right" in _actions(elements, "car")


# ------------------------------------------------------------------------------------------- the ego's actions

def _ego_overtakes(pass_it: bool):
    """The ego starts 20 m behind a slow car, changes to the left lane and (if ``pass_it``) passes it."""
    ego_speed = 15.0 if pass_it else 5.0
    ego = [[ego_speed * DT * k, 1.75 if k < 5 else 5.25, 0.0, ego_speed] for k in range(50)]
    car = [[20.0 + 6.0 * DT * k, 1.75, 0.0, 6.0] for k in range(50)]
    events = [{"time": 1.0, "kind": "lane_change", "actors": ["ego"], "direction": "left"}]
    return _trace([{"ego": e, "Car1": c} for e, c in zip(ego, car)], events)


def test_ego_overtake_is_computed():
    elements = elements_from_trace(_ego_overtakes(True))
    assert {"overtake", "lane_change_left"} <= _actions(elements, "ego")
    assert "overtake" not in _actions(elements, "car")
    # changing lanes without getting past the car is not an overtake
    elements = elements_from_trace(_ego_overtakes(False))
    assert "lane_change_left" in _actions(elements, "ego") and "overtake" not in _actions(elements, "ego")


def test_ego_overtake_of_a_parked_obstacle():
    ego = [[10.0 * DT * k, 1.75 if k < 10 else 5.25, 0.0, 10.0] for k in range(50)]
    obstacle = [[40.0, 1.75, 0.0, 0.0]] * 50
    events = [{"time": 2.0, "kind": "lane_change", "actors": ["ego"], "direction": "left"}]
    elements = elements_from_trace(_trace([{"ego": e, "Obstacle1": o} for e, o in zip(ego, obstacle)], events,
                                          kinds={"ego": "ego", "Obstacle1": "obstacle"}))
    assert "overtake" in _actions(elements, "ego")


def _ego_cuts_in(gap: float):
    """The ego, in the left lane, changes right into the lane of a car ``gap`` metres behind it."""
    ego = [[gap + 12.0 * DT * k, 5.25 if k < 5 else 1.75, 0.0, 12.0] for k in range(50)]
    car = [[12.0 * DT * k, 1.75, 0.0, 12.0] for k in range(50)]
    events = [{"time": 1.0, "kind": "lane_change", "actors": ["ego"], "direction": "right"}]
    return _trace([{"ego": e, "Car1": c} for e, c in zip(ego, car)], events)


def test_ego_cut_in_is_computed():
    elements = elements_from_trace(_ego_cuts_in(10.0))
    assert {"cut_in", "lane_change_right"} <= _actions(elements, "ego")
    assert "cut_in" not in _actions(elements, "car")
    # ... but a lane change 70 m ahead of the car is no cut-in
    assert "cut_in" not in _actions(elements_from_trace(_ego_cuts_in(70.0)), "ego")


def _two_way(ego_drifts: bool):
    """The ego eastbound, an oncoming car westbound; one of them drifts over the centre line."""
    ego, car = [], []
    for k in range(50):
        drift = min(3.5, max(0.0, 0.25 * (k - 10)))
        ego.append([8.0 * DT * k, 1.75 - (drift if ego_drifts else 0.0), 0.0, 8.0])
        car.append([120.0 - 8.0 * DT * k, -1.75 + (0.0 if ego_drifts else drift), math.pi, 8.0])
    return _trace([{"ego": e, "Car1": c} for e, c in zip(ego, car)], map_name="urban_two_way")


def test_drift_goes_to_whoever_left_their_lane():
    elements = elements_from_trace(_two_way(ego_drifts=True))
    assert "drift" in _actions(elements, "ego") and "drift" not in _actions(elements, "car")
    assert "keep_lane" not in _actions(elements, "ego") and "keep_lane" in _actions(elements, "car")
    elements = elements_from_trace(_two_way(ego_drifts=False))
    assert "drift" in _actions(elements, "car") and "drift" not in _actions(elements, "ego")
    assert "keep_lane" in _actions(elements, "ego") and "keep_lane" not in _actions(elements, "car")


def test_ego_brake_stop_and_turn_are_computed():
    ego = _drive(0.0, 12.0, stop_at=40.0)
    elements = elements_from_trace(_trace([{"ego": e} for e in ego]))
    assert {"brake", "stop"} <= _actions(elements, "ego")
    steady = elements_from_trace(_trace([{"ego": e} for e in _drive(0.0, 12.0)]))
    assert not {"brake", "stop", "turn_left", "turn_right"} & _actions(steady, "ego")


# ------------------------------------------------------------------------------------------- collision types

@pytest.mark.parametrize("a, b, expected", [
    ([0, 0, 0.0, 10], [4.8, 0.2, 0.05, 2], "collide_rear_end"),         # front of a into back of b
    ([0, 0, 0.0, 10], [-4.9, -0.3, 0.0, 15], "collide_rear_end"),       # hit from behind
    ([0, 0, 0.0, 10], [4.9, 0.3, math.pi - 0.1, 10], "collide_head_on"),
    ([0, 0, 0.0, 10], [2.0, 2.0, math.pi / 2, 10], "collide_side"),     # T-bone / angle
    ([0, 0, 0.0, 10], [0.5, 1.9, 0.05, 10], "collide_side"),            # sideswipe, same direction
    ([0, 0, 0.0, 10], [0.5, -1.9, math.pi, 10], "collide_side"),        # sideswipe, opposite directions
])
def test_collision_type(a, b, expected):
    assert collision_type(a, b) == expected
    assert collision_type(b, a) == expected  # symmetric


def _crash(car_row, ego_row):
    states = [{"ego": [ego_row[0] - 2.0 * (4 - k), ego_row[1], ego_row[2], ego_row[3]], "Car1": car_row}
              for k in range(5)]
    events = [{"time": 0.8, "kind": "collision", "actors": ["ego", "Car1"]}]
    return elements_from_trace(_trace(states, events))


def test_every_collision_gets_its_type_for_both_actors():
    rear = _crash([24.8, 1.75, 0.0, 0.0], [20.0, 1.75, 0.0, 10.0])
    assert {"collide", "collide_rear_end"} <= _actions(rear, "ego") & _actions(rear, "car")
    assert not {"collide_side", "collide_head_on"} & (_actions(rear, "ego") | _actions(rear, "car"))
    side = _crash([21.0, 3.5, math.pi / 2, 8.0], [20.0, 1.75, 0.0, 10.0])
    assert {"collide", "collide_side"} <= _actions(side, "ego") & _actions(side, "car")
    assert "collide_rear_end" not in _actions(side, "ego")
    head_on = _crash([24.9, 1.75, math.pi, 8.0], [20.0, 1.75, 0.0, 10.0])
    assert {"collide", "collide_head_on"} <= _actions(head_on, "ego") & _actions(head_on, "car")


def test_no_collision_no_collision_type():
    elements = elements_from_trace(_trace([{"ego": e, "Car1": [e[0] + 30, 1.75, 0.0, 10.0]} for e in _drive(0, 10)]))
    assert not {a for _, a in elements.actions if a.startswith("collide")}
