"""sg-roads: the rules SG builds town streets that need a second lane in the ego's direction on the multi-lane
two-way street (``urban_multilane``), not on the one-way highway, and the map runs in the env.

The descriptions' parses are built here per the parser contract (``ParsedDescription``), so these tests do not
depend on how today's parser reads a phrase."""

import math
from pathlib import Path

import pytest

from dv2s_gym.pipeline.sg import rules as sg_rules
from dv2s_gym.pipeline.semantics.parsed import Entity, ParsedDescription
from scenario_bank.safety import check_script
from sg_helpers import generate_from, run_script

MULTI = "urban_multilane"


def _cut_in(road="straight_road", ego_lane=None, car_lane="left", side_rel="left_of"):
    ego = Entity("ego", lane=ego_lane)
    car = Entity("car", lane=car_lane, attrs={"noun": "car"})
    car.add_action("cut_in")
    car.relations.append((side_rel, ego))
    return ParsedDescription(text="On a multi-lane town street a car in the left lane cuts in ahead of the ego.",
                             road=road, entities=[ego, car])


def _ego_changes_lanes_with_oncoming(drift: bool = False):
    ego = Entity("ego")
    ego.add_action("lane_change_left")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("drift" if drift else "keep_lane")
    car.relations.append(("oncoming", ego))
    return ParsedDescription(text="On a four-lane street the ego changes lanes to the left while an oncoming car "
                                  "passes.", road="straight_road", entities=[ego, car])


# ---------------------------------------------------------------------------------------------- map choice

def test_a_town_street_that_needs_a_second_lane_gets_the_multilane_street(monkeypatch):
    result = generate_from(monkeypatch, _cut_in())
    assert result.frame.map == MULTI
    assert "param map = 'urban_multilane'" in result.script
    assert result.elements.road == "straight_road"
    assert not any("highway" in w for w in result.warnings), result.warnings
    assert "param ego_speed = Range(8, 12)" in result.script  # town speeds, not highway ones
    assert check_script(result.script) == []
    assert sg_rules.MAP_ROADS[MULTI] == "straight_road"


def test_a_plain_town_street_stays_one_lane_per_direction(monkeypatch):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("brake")
    car.relations += [("ahead_of", ego), ("same_lane", ego)]
    parsed = ParsedDescription(text="A car ahead of the ego brakes on a town street.", road="straight_road",
                               entities=[ego, car])
    assert generate_from(monkeypatch, parsed).frame.map == "urban_two_way"


def test_a_highway_stays_a_highway(monkeypatch):
    result = generate_from(monkeypatch, _cut_in(road="highway"))
    assert result.frame.map == "highway_straight"
    assert result.elements.road == "highway"


def test_three_lanes_in_one_direction_go_to_the_highway_map_with_a_warning(monkeypatch):
    ego = Entity("ego", lane="middle")
    left = Entity("car", attrs={"noun": "car"})
    left.add_action("keep_lane")
    left.relations.append(("left_of", ego))
    right = Entity("truck", attrs={"noun": "truck"})
    right.add_action("lane_change_left")
    right.relations.append(("right_of", ego))
    parsed = ParsedDescription(text="The ego drives in the middle lane of a town street between a car and a "
                                    "truck.", road="straight_road", entities=[ego, left, right])
    result = generate_from(monkeypatch, parsed)
    assert result.frame.map == "highway_straight"
    assert any("three lanes" in w for w in result.warnings), result.warnings


def test_pedestrians_and_a_lane_change_without_a_road_said_get_the_multilane_street(monkeypatch):
    ego = Entity("ego")
    ego.add_action("lane_change_left")
    ped = Entity("pedestrian", attrs={"noun": "pedestrian"})
    ped.add_action("cross")
    ped.relations.append(("ahead_of", ego))
    parsed = ParsedDescription(text="A pedestrian crosses ahead; the ego changes lanes to the left.", road=None,
                               entities=[ego, ped])
    assert generate_from(monkeypatch, parsed).frame.map == MULTI


# ---------------------------------------------------------------------------------------------- composition

def test_left_and_right_lanes_of_a_two_lane_carriageway_are_neighbours(monkeypatch):
    """'the left lane' beside an ego 'in the right lane' is the next lane, not two lanes over."""
    result = generate_from(monkeypatch, _cut_in(ego_lane="right", car_lane="left"))
    assert result.frame.map == MULTI
    assert not any("lanes side by side" in w for w in result.warnings), result.warnings
    assert "leftLane = laneTuple[1]" in result.script and "leftLane2" not in result.script
    assert "car1 = new Car at leftLane.centerline" in result.script


def test_an_oncoming_car_on_the_multilane_street_drives_in_the_oncoming_lane(monkeypatch):
    result = generate_from(monkeypatch, _ego_changes_lanes_with_oncoming())
    assert result.frame.map == MULTI
    assert "oncomingLane = laneTuple[7]" in result.script
    assert "car1 = new Car at oncomingLane.centerline" in result.script
    assert ("car", "oncoming", "ego") in result.elements.relations
    assert not any("one-way" in w for w in result.warnings), result.warnings


def test_an_oncoming_drift_puts_the_ego_next_to_the_centre_line(monkeypatch):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("drift")
    car.relations.append(("oncoming", ego))
    truck = Entity("truck", attrs={"noun": "truck"})
    truck.add_action("keep_lane")
    truck.relations.append(("right_of", ego))
    truck.add_action("lane_change_left")
    parsed = ParsedDescription(text="An oncoming car drifts over the centre line of a four-lane street.",
                               road="straight_road", entities=[ego, car, truck])
    result = generate_from(monkeypatch, parsed)
    assert result.frame.map == MULTI
    assert "t[1] is None" in result.script  # no lane of the ego's direction left of it: the centre line is
    assert "DriftAndReturn" in result.script and "oncomingLane" in result.script


# ---------------------------------------------------------------------------------------------- simulation

_FOUR_LANES = """\
param map = 'urban_multilane'
model scenic.domains.driving.model

def kerbSide(lane):
    return lane.sections[0]._laneToRight is None

forward = [l for l in network.lanes if l.sections[0].isForward]
backward = [l for l in network.lanes if not l.sections[0].isForward]
inner = [l for l in forward if not kerbSide(l)][0]
outer = [l for l in forward if kerbSide(l)][0]
oncomingInner = [l for l in backward if not kerbSide(l)][0]
oncomingOuter = [l for l in backward if kerbSide(l)][0]

ego = new Car at outer.centerline.pointAlongBy(100), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
changer = new Car at inner.centerline.pointAlongBy(125), with speed 10,
    with behavior LaneChangeBehavior(laneSectionToSwitch=outer.sections[0], target_speed=10)
lead = new Car at outer.centerline.pointAlongBy(170), with speed 9,
    with behavior FollowLaneBehavior(target_speed=9)
oncoming1 = new Car at oncomingInner.centerline.pointAlongBy(-200), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
oncoming2 = new Car at oncomingOuter.centerline.pointAlongBy(-230), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
"""


@pytest.mark.slow
def test_the_multilane_street_runs_with_traffic_on_every_lane(tmp_path):
    """Cars on both lanes of both directions, a lane change in the ego's direction, oncoming traffic."""
    import gymnasium as gym

    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    path = Path(tmp_path) / "four_lanes.scenic"
    path.write_text(_FOUR_LANES)
    env = gym.make("dv2s_gym:DV2S-v0", scenario=str(path), config={"duration": 6, "ego_policy": "scenic"})
    try:
        env.reset(seed=0)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(1)
            done = terminated or truncated
        trace = env.unwrapped.trace
    finally:
        env.close()
    first, last = trace.states[0], trace.states[-1]
    assert len(first) == 5
    lateral = sorted({round(state[1], 2) for state in first.values()})
    assert lateral == [-5.25, -1.75, 1.75, 5.25]  # every lane of the street holds a car (highway-env: y down)
    for name, state in first.items():
        going_right = abs(state[2]) < 0.1
        moved = last[name][0] - state[0]
        assert (moved > 30) if going_right else (moved < -30), name  # each drives its lane's way
        assert state[3] <= 50 / 3.6
    changes = [e for e in trace.events if e["kind"] == "lane_change"]
    assert changes and changes[0]["direction"] == "right"
    elements = elements_from_trace(trace)
    assert elements.road == "straight_road"
    assert ("car", "oncoming", "ego") in elements.relations
    assert not any(e["kind"] == "collision" for e in trace.events)


@pytest.mark.slow
def test_a_cut_in_on_the_multilane_street_shows_in_the_trace(monkeypatch):
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = generate_from(monkeypatch, _cut_in())
    hits = 0
    for seed in range(3):
        trace = run_script(result.script, 8.0, seed)
        elements = elements_from_trace(trace)
        assert elements.road == "straight_road"
        ego_speeds = [states["ego"][3] for states in trace.states]
        assert max(ego_speeds) < 14.0  # town speed
        hits += ("car", "cut_in") in elements.actions
    assert hits >= 2, hits


@pytest.mark.slow
def test_a_crossing_pedestrian_on_the_multilane_street_starts_off_the_lanes(monkeypatch):
    ego = Entity("ego")
    ego.add_action("lane_change_left")
    ped = Entity("pedestrian", attrs={"noun": "pedestrian", "cross_dirs": [("left_to_right", 1)]})
    ped.add_action("cross")
    ped.relations.append(("ahead_of", ego))
    parsed = ParsedDescription(text="On a four-lane street a pedestrian crosses from the left.",
                               road="straight_road", entities=[ego, ped])
    result = generate_from(monkeypatch, parsed)
    assert result.frame.map == MULTI
    for seed in range(2):
        trace = run_script(result.script, 1.0, seed)
        name = next(n for n in trace.states[0] if trace.kinds.get(n) == "pedestrian")
        # the street's lanes span |y| <= 7 m (two 3.5 m lanes each side of the centre line)
        assert abs(trace.states[0][name][1]) > 7.0, trace.states[0][name]
        assert math.isfinite(trace.states[-1][name][0])


# ---------------------------------------------------------------------------------------------- roundabout

RING = "urban_roundabout"


def _circulating_from_the_left(collide: bool = True, cut_in: bool = False):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    if collide:
        car.add_action("collide")
        ego.add_action("collide")
    if cut_in:
        car.add_action("cut_in")
    car.relations.append(("left_of", ego))
    if not cut_in:
        car.relations.append(("crossing_path", ego))
    return ParsedDescription(text="The ego enters a roundabout; a car already circulating comes from its left.",
                             road="roundabout", entities=[ego, car])


def test_a_roundabout_gets_the_roundabout_map_without_a_warning(monkeypatch):
    result = generate_from(monkeypatch, _circulating_from_the_left())
    assert result.frame.map == RING
    assert result.elements.road == "roundabout"
    assert sg_rules.MAP_ROADS[RING] == "roundabout" and RING in sg_rules.JUNCTION_MAPS
    assert not any("roundabout" in w for w in result.warnings), result.warnings
    assert check_script(result.script) == []
    # already circulating: it starts on the ring (its connecting lane), not on its approach arm
    assert "car1 = new Car at car1Maneuver.connectingLane.centerline.pointAlongBy(" in result.script
    assert "m0.type is ManeuverType.STRAIGHT" in result.script  # it passes the ego's entry


def test_ring_lengths_match_the_map():
    """The entry curve and the quarter ring the composer times circulating vehicles with are those of the map."""
    from scenario_bank.map_cache import load_network
    from scenario_bank.maps import resolve_map

    net = load_network(resolve_map(RING))
    (junction,) = net.intersections
    right = next(m for m in junction.maneuvers if m.type.name == "RIGHT_TURN")
    straight = next(m for m in junction.maneuvers if m.type.name == "STRAIGHT" and m.startLane is right.startLane)
    # a first-exit path is two entry curves and a quarter ring less two entry angles; the second exit one
    # quarter ring more
    assert straight.connectingLane.centerline.length - right.connectingLane.centerline.length == pytest.approx(
        sg_rules.RING_QUARTER, abs=0.3)
    assert 10.0 < sg_rules.RING_ENTRY < right.connectingLane.centerline.length / 2


@pytest.mark.slow
def test_a_vehicle_circulating_from_the_left_hits_the_entering_ego(monkeypatch):
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = generate_from(monkeypatch, _circulating_from_the_left())
    hits = 0
    for seed in range(3):
        trace = run_script(result.script, 8.0, seed)
        elements = elements_from_trace(trace)
        assert elements.road == "roundabout"
        hits += ("car", "collide") in elements.actions and ("car", "left_of", "ego") in elements.relations
    assert hits >= 2, hits


@pytest.mark.slow
def test_a_vehicle_circulating_from_the_left_passes_before_the_ego_when_nobody_collides(monkeypatch):
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = generate_from(monkeypatch, _circulating_from_the_left(collide=False))
    assert "DriveRoute(" in result.script.split("car1 = new Car")[1]  # it has the right of way on the ring
    for seed in range(3):
        trace = run_script(result.script, 8.0, seed)
        assert not any(e["kind"] == "collision" for e in trace.events)
        car = next(n for n in trace.states[0] if n != "ego")
        gaps = [math.hypot(s["ego"][0] - s[car][0], s["ego"][1] - s[car][1]) for s in trace.states]
        assert min(gaps) > 5.0  # it is gone past the ego's entry before the ego gets there
        assert min(s[car][3] for s in trace.states) > 4.0  # and it did not stop for the ego
        elements = elements_from_trace(trace)
        assert ("car", "left_of", "ego") in elements.relations and elements.road == "roundabout"
