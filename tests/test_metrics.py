"""The paper's metrics and the semantics of simulated episodes."""

import math

import pytest

from dv2s_gym.pipeline.metrics import e2e_sc, hallucination_rate, mean_sd, scs, semantic_preservation
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from envs.trace import EpisodeTrace

GT = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "brake"]],
      "relations": [["car", "ahead_of", "ego"]]}


def test_metric_definitions():
    said = {"road": "highway", "participants": ["ego", "car", "car"], "actions": [["car", "brake"]], "relations": []}
    # GT has 5 elements (road, ego, car#1, car brake, car ahead_of ego); 4 are said; said has 5 (one extra car).
    assert scs(GT, said) == pytest.approx(4 / 5)
    assert hallucination_rate(GT, said) == pytest.approx(1 - 4 / 5)
    assert semantic_preservation(said, GT) == pytest.approx(4 / 5)
    assert e2e_sc(GT, GT) == 1.0
    assert scs(GT, {}) == 0.0 and hallucination_rate(GT, {}) == 0.0
    assert mean_sd([1.0, 0.0])["mean"] == 0.5 and mean_sd([1.0])["sd"] == 0.0
    assert math.isnan(mean_sd([])["mean"])


def _trace(states, events=(), kinds=None, map_name="highway_straight"):
    return EpisodeTrace(scenario="t", source="", seed=0, scene_seed=0, params={"map": f"/x/{map_name}.xodr"},
                        config={"policy_frequency": 5}, states=list(states), events=list(events), kinds=kinds or {})


def test_trace_semantics_lead_vehicle_brakes_then_cut_in():
    # highway-env frame: both drive +x; the car is 20 m ahead in the same lane and brakes from 20 to 5 m/s.
    states = []
    ego_x, car_x, car_v = 0.0, 20.0, 20.0
    for step in range(30):
        car_v = max(5.0, car_v - 1.5) if step >= 5 else car_v
        states.append({"ego": [ego_x, 0.0, 0.0, 15.0], "Car1": [car_x, 0.0, 0.0, car_v]})
        ego_x += 3.0
        car_x += car_v * 0.2
    elements = elements_from_trace(_trace(states))
    assert elements.road == "highway"
    assert ("car", "brake") in elements.actions
    assert ("car", "ahead_of", "ego") in elements.relations and ("car", "same_lane", "ego") in elements.relations
    assert e2e_sc(GT, elements) == 1.0


def test_trace_semantics_pedestrian_crossing_and_left_turn():
    states = []
    for step in range(40):
        t = step * 0.2
        # Scenic-style left turn seen in highway-env's frame: heading goes from 0 to -pi/2.
        heading = -min(1.0, t / 6.0) * math.pi / 2
        states.append({"ego": [5.0 * t, 0.0, heading, 5.0], "Pedestrian1": [30.0, 6.0 - 1.5 * t, -math.pi / 2, 1.5]})
    elements = elements_from_trace(_trace(states, kinds={"ego": "ego", "Pedestrian1": "pedestrian"},
                                          map_name="urban_crossroads"))
    assert elements.road == "intersection"
    assert ("ego", "turn_left") in elements.actions
    assert ("pedestrian", "cross") in elements.actions


def test_trace_semantics_collisions_and_lane_changes_come_from_events():
    states = [{"ego": [3.0 * k, 0.0, 0.0, 15.0], "Car1": [10 + 3.0 * k, -3.5 if k < 5 else 0.0, 0.0, 15.0]}
              for k in range(20)]
    events = [{"time": 1.0, "kind": "lane_change", "actors": ["Car1"], "direction": "right"},
              {"time": 2.0, "kind": "collision", "actors": ["ego", "Car1"]}]
    elements = elements_from_trace(_trace(states, events))
    assert ("car", "lane_change_right") in elements.actions and ("car", "cut_in") in elements.actions
    assert ("ego", "collide") in elements.actions and ("car", "collide") in elements.actions


def test_trace_semantics_pedestrian_crossing_ahead_of_a_stopped_ego():
    # The ego brakes to a stop 8 m before the pedestrian's line: the pedestrian still crossed its path.
    ego, x, v = [], 0.0, 10.0
    for _ in range(40):
        v = max(0.0, v - 0.6)
        x += v * 0.2
        ego.append([x, 0.0, 0.0, v])

    def states(line_x):
        return [{"ego": e, "Pedestrian1": [line_x, 5.0 - 0.3 * k, -math.pi / 2, 1.5]} for k, e in enumerate(ego)]

    kinds = {"ego": "ego", "Pedestrian1": "pedestrian"}
    elements = elements_from_trace(_trace(states(x + 8.0), kinds=kinds, map_name="urban_two_way"))
    assert ("pedestrian", "crossing_path", "ego") in elements.relations
    # ... but one crossing 60 m beyond where the ego stopped did not.
    elements = elements_from_trace(_trace(states(x + 60.0), kinds=kinds, map_name="urban_two_way"))
    assert ("pedestrian", "crossing_path", "ego") not in elements.relations


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_trace_semantics_car_merging_from_a_side_road(side):
    # A car comes down a side road (heading +-90 degrees to the ego's), turns into the ego's lane ahead of it.
    states = []
    for step in range(40):
        t = step * 0.2
        turn = min(1.0, t / 4.0)
        car = [30.0 + 8.0 * max(0.0, t - 2.0), side * 15.0 * (1.0 - turn), -side * (math.pi / 2) * (1 - turn), 6.0]
        states.append({"ego": [6.0 * t, 0.0, 0.0, 6.0], "Car1": car})
    elements = elements_from_trace(_trace(states, map_name="urban_t_junction"))
    assert ("car", "merge") in elements.actions
    # A car that stays on the side road does not merge.
    stays = [{**s, "Car1": [30.0, side * 15.0, -side * math.pi / 2, 0.0]} for s in states]
    assert ("car", "merge") not in elements_from_trace(_trace(stays, map_name="urban_t_junction")).actions


def test_an_undirected_lane_change_is_matched_by_either_direction_and_not_the_reverse():
    undirected = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "lane_change"]]}
    left = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "lane_change_left"]]}
    right = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "lane_change_right"]]}
    assert semantic_preservation(undirected, left) == 1.0
    assert semantic_preservation(undirected, right) == 1.0
    # a directed label is not satisfied by an undirected description of it
    assert semantic_preservation(left, undirected) == 0.75
    assert semantic_preservation(left, right) == 0.75
    # the truth says left, the description only "a lane change": nothing hallucinated
    assert hallucination_rate(left, undirected) == 0.0
    assert hallucination_rate(undirected, left) == 0.25
