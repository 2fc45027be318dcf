"""Kerbside parking lanes: the ``urban_parking`` map, vehicles on its parking lanes in DV2S-v0 (parked, pulling
out, pulling over) and the rules SG putting parked / pulling-out vehicles there."""

from __future__ import annotations

from pathlib import Path

import pytest

from dv2s_gym.pipeline.sg.rules import PARKING_STREET, generate_rules
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from scenario_bank.maps import MAPS_DIR
from scenario_bank.maps.dimensions import LANE_WIDTH, PARKING_WIDTH, SIDEWALK_WIDTH
from sg_helpers import run_script

PARKING_CENTRE = LANE_WIDTH + PARKING_WIDTH / 2  # lateral offset of a parking lane's centre from the road centre


def _actions(elements, who):
    return {a for k, a in elements.actions if k == who}


def _other(trace, kind="car"):
    """Trace name of the one non-ego actor of ``kind`` (the env names actors by class, not by variable)."""
    (name,) = [n for n, k in trace.kinds.items() if k == kind and n != "ego"]
    return name


def test_urban_parking_has_a_parking_lane_at_each_kerb():
    """Scenic reads the parking lanes as shoulders (not lanes); one driving lane and one sidewalk per direction."""
    from scenic.domains.driving.roads import Network

    net = Network.fromFile(MAPS_DIR / "urban_parking.xodr", useCache=False, writeCache=False)
    (road,) = net.roads
    assert len(road.forwardLanes.lanes) == 1 and len(road.backwardLanes.lanes) == 1 and len(net.lanes) == 2
    assert len(net.shoulders) == 2 and len(net.sidewalks) == 2
    for shoulder in net.shoulders:
        assert shoulder.polygon.area == pytest.approx(PARKING_WIDTH * 600.0, rel=0.01)
        ys = [p[1] for p in shoulder.polygon.exterior.coords]
        assert min(abs(y) for y in ys) == pytest.approx(LANE_WIDTH, abs=0.01)
        assert max(abs(y) for y in ys) == pytest.approx(LANE_WIDTH + PARKING_WIDTH, abs=0.01)
    for sidewalk in net.sidewalks:
        ys = [p[1] for p in sidewalk.polygon.exterior.coords]
        assert max(abs(y) for y in ys) == pytest.approx(LANE_WIDTH + PARKING_WIDTH + SIDEWALK_WIDTH, abs=0.01)
    # each parking lane is the shoulder of the driving lane beside it
    for group in (road.forwardLanes, road.backwardLanes):
        assert group._shoulder is not None


def test_urban_parking_in_highway_env_parking_lanes_are_road_but_not_lanes():
    """highway-env gets the two driving lanes only; ``on_shoulder`` says where the parking lanes are."""
    from envs.road_network import load_road_network

    converted = load_road_network(str(MAPS_DIR / "urban_parking.xodr"))
    graph = converted.hw_network.graph
    edges = [(a, b) for a in graph for b in graph[a]]
    assert len(edges) == 2 and all(len(graph[a][b]) == 1 for a, b in edges)
    for y in (PARKING_CENTRE, -PARKING_CENTRE, LANE_WIDTH + 0.2, -(LANE_WIDTH + PARKING_WIDTH - 0.2)):
        assert converted.on_shoulder((300.0, y)), y
    for y in (0.0, LANE_WIDTH / 2, -LANE_WIDTH / 2, LANE_WIDTH + PARKING_WIDTH + 1.0):
        assert not converted.on_shoulder((300.0, y)), y
    # a map without shoulders
    assert not load_road_network(str(MAPS_DIR / "urban_two_way.xodr")).on_shoulder((300.0, PARKING_CENTRE))


_KERB_SCRIPT = """
param map = 'urban_parking'
model scenic.domains.driving.model

behavior HoldStill():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

behavior SteerTo(line, target, speed, stopAfter):
    # steer gently (at most 0.3 rad off the road) to `target` m beside `line` (left positive), then drive on
    # along it or, with stopAfter, brake to a stop there
    reference = self.heading
    while abs(line.signedDistanceTo(self.position) - target) > 0.3 or abs(self.heading - reference) > 0.05:
        offset = line.signedDistanceTo(self.position) - target
        wanted = max(-0.3, min(0.3, -0.25 * offset))
        steer = max(-0.3, min(0.3, -1.5 * (wanted - (self.heading - reference))))
        take SetThrottleAction(0.5 if self.speed < speed else 0), SetBrakeAction(0), SetSteerAction(steer)
    if stopAfter:
        do HoldStill()
    do FollowLaneBehavior(target_speed=speed)

behavior PullOverThenStop(line, target, speed):
    do FollowLaneBehavior(target_speed=speed) for 1 seconds
    do SteerTo(line, target, speed, True)

behavior PullOut(line, speed):
    do HoldStill() for 1 seconds
    do SteerTo(line, 0, speed, False)

lane = [l for l in network.lanes if l.sections[0].isForward][0]
spot = new OrientedPoint at lane.centerline.pointAlongBy(100), facing roadDirection
ego = new Car right of spot by 2.0, facing spot.heading,
    with regionContainedIn everywhere,
    with speed 0,
    with behavior {ego}
parkedSpot = new OrientedPoint at lane.centerline.pointAlongBy(130), facing roadDirection
parked = new Car right of parkedSpot by 2.0, facing parkedSpot.heading,
    with regionContainedIn everywhere,
    with speed 0,
    with behavior HoldStill()
require network.shoulderAt(parked) is not None
require network.shoulderAt(ego) is not None
"""


def _kerb_trace(tmp_path, ego_behavior, seconds=9.0):
    path = Path(tmp_path) / "kerb.scenic"
    path.write_text(_KERB_SCRIPT.replace("{ego}", ego_behavior))
    return run_script(str(path), seconds)


@pytest.mark.slow
def test_a_parked_car_stands_on_the_parking_lane_and_the_ego_pulls_out_of_it(tmp_path):
    trace = _kerb_trace(tmp_path, "PullOut(lane.centerline, 8)")
    first, last = trace.states[0], trace.states[-1]
    parked = _other(trace)
    # highway-env's y points down: the right-hand parking lane of the +x lane is at y = +PARKING_CENTRE
    assert first[parked][1] == pytest.approx(PARKING_CENTRE, abs=0.2)
    assert first["ego"][1] == pytest.approx(PARKING_CENTRE, abs=0.2)
    for state in trace.states:
        assert state[parked][:2] == pytest.approx(first[parked][:2], abs=0.05)  # it stays parked
    assert last["ego"][1] == pytest.approx(LANE_WIDTH / 2, abs=0.4)  # in the driving lane
    assert last["ego"][0] - first["ego"][0] > 20
    assert not any(e["kind"] in ("off_road", "collision") for e in trace.events)
    elements = elements_from_trace(trace)
    assert elements.road == "straight_road"
    assert "pull_out" in _actions(elements, "ego")


@pytest.mark.slow
def test_the_ego_pulls_over_onto_the_parking_lane_without_leaving_the_road(tmp_path):
    script = _KERB_SCRIPT.replace("ego = new Car right of spot by 2.0, facing spot.heading,",
                                  "ego = new Car at lane.centerline.pointAlongBy(40),") \
        .replace("    with speed 0,\n    with behavior {ego}", "    with speed 8,\n    with behavior {ego}") \
        .replace("require network.shoulderAt(ego) is not None\n", "")
    path = Path(tmp_path) / "pull_over.scenic"
    path.write_text(script.replace("{ego}", f"PullOverThenStop(lane.centerline, -{PARKING_CENTRE - LANE_WIDTH / 2}, 8)"))
    trace = run_script(str(path), 9.0)
    last = trace.states[-1]
    assert last["ego"][1] == pytest.approx(PARKING_CENTRE, abs=0.4)  # on the parking lane
    assert last["ego"][3] < 0.5  # stopped there
    assert last["ego"][0] < trace.states[0][_other(trace)][0] - 4  # short of the parked car
    assert not any(e["kind"] in ("off_road", "collision") for e in trace.events)


def test_a_pull_out_of_a_parking_space_gets_the_parking_street():
    result = generate_rules("A car pulls out of a parking space on the right in front of the ego.")
    assert result.frame.map == PARKING_STREET
    assert "param map = 'urban_parking'" in result.script
    assert "car1 = new Car right of car1Spot by Range(1.9, 2.1)" in result.script
    assert result.elements.road == "straight_road"


def test_a_street_said_to_have_parking_gets_the_parking_street_and_parked_cars_stand_on_it():
    result = generate_rules("On a street with on street parking, a car is parked on the right side ahead of the ego.")
    assert result.frame.map == PARKING_STREET
    assert "car1 = new Car right of car1Spot by Range(1.9, 2.1)" in result.script


def test_a_plain_street_keeps_the_street_without_parking_lanes():
    assert generate_rules("On a two-lane street a car ahead of the ego brakes suddenly.").frame.map == "urban_two_way"


@pytest.mark.slow
def test_a_car_pulling_out_of_the_parking_lane_is_traced_as_pulling_out():
    result = generate_rules("A car pulls out of a parking space on the right in front of the ego.")
    trace = run_script(result.script, 10.0)
    first = trace.states[0]
    assert abs(first[_other(trace)][1]) == pytest.approx(PARKING_CENTRE, abs=0.3)  # parked on the parking lane
    elements = elements_from_trace(trace)
    assert "pull_out" in _actions(elements, "car")
    assert not any(e["kind"] == "off_road" for e in trace.events)


@pytest.mark.slow
def test_the_ego_pulling_out_of_a_parking_space_stays_on_the_road():
    result = generate_rules("The ego pulls out of a parking space into the street.")
    assert result.frame.map == PARKING_STREET
    trace = run_script(result.script, 10.0)
    assert abs(trace.states[0]["ego"][1]) == pytest.approx(PARKING_CENTRE, abs=0.3)
    assert not any(e["kind"] == "off_road" for e in trace.events)
    assert "pull_out" in _actions(elements_from_trace(trace), "ego")




def test_a_car_stopped_on_the_hard_shoulder_stands_on_the_shoulder():
    result = generate_rules("On the highway a car is stopped on the hard shoulder ahead of the ego.")
    assert result.frame.map == "highway_straight"
    assert "car1 = new Car right of car1Spot by Range(2.15, 2.35)" in result.script
    assert "t[3] is None" in result.script  # beside the rightmost lane
    # a car stopped in a lane stays in the lane
    plain = generate_rules("On the highway a car ahead of the ego stops suddenly.")
    assert "right of car1Spot" not in plain.script


@pytest.mark.slow
def test_a_car_stopped_on_the_hard_shoulder_is_passed_without_a_crash():
    trace = run_script(generate_rules("On the highway a car is stopped on the hard shoulder ahead of the ego.").script,
                       8.0)
    car = _other(trace)
    first, last = trace.states[0], trace.states[-1]
    assert abs(first[car][1]) == pytest.approx(abs(first["ego"][1]) + 3.25, abs=0.15)  # on the shoulder
    assert last[car][:2] == pytest.approx(first[car][:2], abs=0.05)
    assert last["ego"][0] > first[car][0]  # the ego drove past it
    assert not any(e["kind"] in ("collision", "off_road") for e in trace.events)


@pytest.mark.slow
def test_the_ego_parked_on_the_hard_shoulder_pulls_out_into_the_right_lane():
    result = generate_rules("ego parked on hwy shoulder, pulls out into R lane; car approaching from behind in that "
                            "lane")
    assert result.frame.map == "highway_straight"
    trace = run_script(result.script, 10.0)
    first, last = trace.states[0], trace.states[-1]
    car = _other(trace)
    assert abs(first["ego"][1] - first[car][1]) == pytest.approx(3.25, abs=0.15)  # ego on the shoulder, car in lane
    assert abs(last["ego"][1] - first[car][1]) < 0.5  # the ego ends in that lane
    assert not any(e["kind"] == "off_road" for e in trace.events)
    assert "pull_out" in _actions(elements_from_trace(trace), "ego")


def test_a_pedestrian_stepping_out_between_parked_cars_may_stand_on_the_parking_lane():
    """The parking lane is no walkable region: a pedestrian at the kerb of the parking street is let stand on it."""
    result = generate_rules("A child runs out from behind two parked cars on the right into the path of the ego.")
    assert result.frame.map == PARKING_STREET
    spawn = result.script.split("# 4. Spawn positions")[1]
    pedestrian = spawn[spawn.index("= new Pedestrian"):]
    assert "with regionContainedIn everywhere" in pedestrian.split("with behavior")[0]


@pytest.mark.slow
def test_a_child_running_out_between_parked_cars_crosses_in_the_run():
    from dv2s_gym.pipeline.convert import check_scenario

    result = generate_rules("A child runs out from behind two parked cars on the right into the path of the ego.")
    check = check_scenario(result.script, seed=0, seconds=10.0)
    assert check.ran, check.error
    assert ("pedestrian", "cross") in check.simulated_elements.actions
    assert ("car", "right_of", "ego") in check.simulated_elements.relations


def test_parked_cars_on_the_parking_street_stand_at_the_kerb_not_in_the_egos_lane():
    result = generate_rules("A pedestrian steps out between parked cars along the curb in front of the ego.")
    assert result.frame.map == PARKING_STREET
    car = next(a for a in result.frame.actors if a.kind == "car")
    assert car.role == "far_side" and "right_of" in car.relations and "same_lane" not in car.relations
    assert "car1_1 = new Car right of car1_1Spot by Range(1.9, 2.1)" in result.script
    assert ("car", "right_of", "ego") in result.elements.relations
