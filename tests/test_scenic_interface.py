"""The Scenic simulator interface for highway-env, behaviour by behaviour.

Each fixture writes a small Scenic program, runs it in ``DV2SEnv`` with the
script's ego behaviour driving (``ego_policy="scenic"``) for a few simulated
seconds, and the tests assert what highway-env simulated: positions, headings
and speeds of ``env.unwrapped.road.vehicles`` (highway-env frame: ``y`` is the
negated Scenic ``y``, heading 0 is ``+x`` and grows clockwise on screen) and the
episode's info.

Compiling a Scenic program takes about 3 s (Scenic re-parses the world model
every time), so the programs put many independent actors on one map, far enough
apart not to interact, and run once per module; each actor is named with
``with name 'x'`` and appears in highway-env as ``x`` (``x1``, ``x2``... when several share it).

Covered here: the driving domain's behaviour library (lane following, lane
changes, trajectories and turns through junctions, collision avoidance, walking,
constant throttle) and user behaviours built from the driving-domain actions.
``test_scenic_interface_scenarios.py`` covers requirements and termination,
actor kinds, VerifAI, model substitution, CARLA towns and the ego policy.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import scenic  # noqa: F401  (a core dependency: a broken install fails here)

from envs.coordinates import scenic_to_hw_heading  # noqa: E402
from envs.road_network import load_road_network  # noqa: E402
from envs.scenic_highway.actors import MAX_ACCELERATION, MAX_BRAKING  # noqa: E402
from scenario_bank.maps import resolve_map  # noqa: E402
from scenic.domains.driving.roads import ManeuverType  # noqa: E402
from scenic_sim_helpers import (  # noqa: E402
    TOWN01,
    converted_network,
    hw_lane_of,
    lane_offset,
    lateral_errors,
    run_scenario,
    scenic_heading,
    wrap,

)

pytestmark = pytest.mark.usefixtures("in_process_simulator")

# --------------------------------------------------------------------------- the highway program
#
# highway_straight: four lanes along +x (Scenic heading -90 deg), 2000 m long.
# Scenic lane i is centred at Scenic y = -12.25 + 3.5 i, i.e. highway-env y = 12.25 - 3.5 i;
# lane 0 is the rightmost. Every actor below keeps clear of the others for 10 s.

HIGHWAY_PROGRAM = """
param map = 'highway_straight'
model scenic.domains.driving.model

L0, L1, L2, L3 = network.lanes[0], network.lanes[1], network.lanes[2], network.lanes[3]


def spot(lane, x, right=0):
    pt = new OrientedPoint at lane.centerline.pointAlongBy(x), facing roadDirection
    return pt offset along pt.heading by (right, 0)

behavior Hold(action):
    take action
    while True:
        wait

behavior Repeat(action):
    while True:
        take action

behavior ChangeRight(speed):
    do LaneChangeBehavior(laneSectionToSwitch=L1.sections[0].laneToRight, target_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior Teleport(destination):
    wait
    take SetPositionAction(destination)
    while True:
        wait

behavior Careful(lead, speed, threshold):
    try:
        do FollowLaneBehavior(target_speed=speed)
    interrupt when (distance from self to lead) < threshold:
        take SetThrottleAction(0), SetBrakeAction(1)

# lane following: 0.8 m right of the centre at the target speed, and from standstill
ego = new Car at spot(L2, 100, right=0.8), with speed 10, with behavior FollowLaneBehavior(target_speed=10)
new Car at spot(L3, 100, right=0.8), with name 'fast', with speed 30,
    with behavior FollowLaneBehavior(target_speed=30)
new Car at spot(L3, 700), with name 'standstill', with behavior FollowLaneBehavior(target_speed=15)

# lane change from lane 1 to lane 0
new Car at spot(L1, 100), with name 'lanechange', with speed 15, with behavior ChangeRight(15)

# throttle behaviours and actions
new Car at spot(L2, 1100), with name 'constant', with behavior ConstantThrottleBehavior(0.5)
new Car at spot(L2, 1400), with name 'accelerate', with behavior AccelerateForwardBehavior()
new Car at spot(L3, 1300), with name 'floor', with behavior Repeat(SetThrottleAction(1.0))
new Car at spot(L1, 400), with name 'brake', with speed 15,
    with behavior Repeat(SetBrakeAction(1.0))
new Car at spot(L0, 850), with name 'steerright', with speed 8, with behavior Repeat(SetSteerAction(0.3))
new Car at spot(L0, 540), with name 'steerleft', with speed 8, with behavior Repeat(SetSteerAction(-0.3))
new Car at spot(L3, 1000), with name 'setspeed', with behavior Hold(SetSpeedAction(12))
new Car at spot(L2, 1700), with name 'setvelocity', with behavior Hold(SetVelocityAction(7, 0))
new Car at spot(L2, 400), with name 'teleport', with speed 5, with behavior Teleport(900 @ -5.25)

# collision avoidance: library behaviour and a user behaviour with `interrupt when`
new Car at spot(L1, 600), with name 'avoid', with speed 10,
    with behavior DriveAvoidingCollisions(target_speed=10, avoidance_threshold=20)
new Car at spot(L1, 700), with name 'stopped'
new Car at spot(L0, 1500), with name 'avoidfast', with speed 15,
    with behavior DriveAvoidingCollisions(target_speed=15, avoidance_threshold=25)
new Car at spot(L0, 1620), with name 'stopped'
carefulLead = new Car at spot(L1, 980), with name 'stopped'
new Car at spot(L1, 900), with name 'careful', with speed 12, with behavior Careful(carefulLead, 12, 18)

require always ego.speed < 100
"""

DURATION = 10.0


@pytest.fixture(scope="module")
def highway():
    return run_scenario(HIGHWAY_PROGRAM, DURATION)


@pytest.mark.slow
def test_highway_program_runs_to_the_end_without_collisions(highway):
    assert highway.truncated and not highway.terminated
    assert highway.duration == pytest.approx(DURATION)
    assert highway.final_info["scenic_status"] == "running"  # `require always` held
    assert highway.events("collision") == []


# --------------------------------------------------------------------------- FollowLaneBehavior


@pytest.mark.slow
@pytest.mark.parametrize("name, speed, lane", [("ego", 10, "road1_lane2"), ("fast", 30, "road1_lane3")])
def test_follow_lane_converges_to_the_lane_centre_and_holds_speed(highway, name, speed, lane):
    track = highway.track(name)
    assert all(s.lane_index == hw_lane_of(highway, lane) for s in track)
    errors = lateral_errors(highway, name)
    assert errors[0] == pytest.approx(0.8, abs=0.01)
    assert errors.max() < 0.85  # never swings out further than where it started
    assert errors[-25:].max() < 0.05  # settled during the last 5 s
    headings = highway.headings(name)
    assert np.abs(headings).max() < math.radians(10)
    assert np.abs(headings[-25:]).max() < math.radians(0.5)
    speeds = highway.speeds(name)
    assert np.abs(speeds - speed).max() < 0.5
    xs = highway.xy(name)[:, 0]
    assert xs[-1] - xs[0] == pytest.approx(speed * DURATION, rel=0.02)


def test_follow_lane_accelerates_from_standstill_to_the_target_speed(highway):
    speeds = highway.speeds("standstill")
    assert speeds[0] == 0
    assert speeds.max() < 15.1  # no overshoot
    assert np.abs(speeds[-15:] - 15).max() < 0.3  # last 3 s
    assert lateral_errors(highway, "standstill").max() < 0.01


# --------------------------------------------------------------------------- LaneChangeBehavior


def test_lane_change_ends_centred_in_the_adjacent_lane(highway):
    track = highway.track("lanechange")
    start, final = track[0], track[-1]
    assert start.lane_index == hw_lane_of(highway, "road1_lane1")
    assert final.lane_index == hw_lane_of(highway, "road1_lane0")
    ys = highway.xy("lanechange")[:, 1]
    assert final.y - start.y == pytest.approx(3.5, abs=0.05)  # lane 0 is 3.5 m to the right
    assert ys.max() - start.y < 3.5 + 0.2  # barely overshoots
    assert abs(final.heading) < math.radians(0.5)
    assert np.abs(highway.headings("lanechange")).max() < math.radians(15)
    assert abs(final.speed - 15) < 0.2
    changes = [e for e in highway.events("lane_change") if e["actors"] == ["lanechange"]]
    assert [e["direction"] for e in changes] == ["right"]


# --------------------------------------------------------------------------- throttle behaviours and actions


@pytest.mark.parametrize("name", ["constant", "accelerate"])
def test_half_throttle_behaviours_accelerate_straight_ahead(highway, name):
    speeds = highway.speeds(name)
    # the behaviour's first action is taken at time 0, so after t seconds v = 2.5 t
    times = np.arange(len(speeds)) * highway.timestep
    assert speeds == pytest.approx(0.5 * MAX_ACCELERATION * times, abs=1e-6)
    assert np.abs(highway.headings(name)).max() < 1e-9
    ys = highway.xy(name)[:, 1]
    assert np.abs(ys - ys[0]).max() < 1e-9


def test_set_throttle_action_full_throttle(highway):
    speeds = highway.speeds("floor")
    below_top_speed = speeds[1:] < 40  # highway-env caps vehicle speeds at 40 m/s
    assert below_top_speed[:30].all()
    assert (np.diff(speeds) / highway.timestep)[below_top_speed] == pytest.approx(MAX_ACCELERATION)


def test_set_brake_action_stops_the_car_and_never_reverses(highway):
    speeds = highway.speeds("brake")
    assert speeds[0] == 15 and np.all(speeds >= 0)
    stop = int(np.argmax(speeds == 0))
    assert stop > 0 and np.all(speeds[stop:] == 0)
    assert stop * highway.timestep == pytest.approx(15 / MAX_BRAKING, abs=highway.timestep)
    xs = highway.xy("brake")[:, 0]
    assert np.all(np.diff(xs) >= 0)  # never rolls backwards
    assert xs[-1] - xs[0] == pytest.approx(15**2 / (2 * MAX_BRAKING), rel=0.05)
    assert np.all(xs[stop:] == xs[stop])


@pytest.mark.parametrize("name, steer", [("steerright", 0.3), ("steerleft", -0.3)])
def test_set_steer_action_turns_the_right_way(highway, name, steer):
    """Positive steer turns right: clockwise seen from above, the Scenic heading decreases."""
    headings = np.unwrap([scenic_heading(h) for h in highway.headings(name)])
    turning = np.diff(headings[:8])  # first 1.4 s
    assert np.all(np.sign(turning[1:]) == -np.sign(steer))
    assert np.all(np.abs(turning[1:]) > 0.1)
    # and the car ends up on that side of its initial direction of travel (+x, Scenic -90 deg)
    xy = highway.xy(name)
    scenic_dy = -(xy[7, 1] - xy[0, 1])
    assert (scenic_dy < -1) if steer > 0 else (scenic_dy > 1)
    assert highway.speeds(name) == pytest.approx(8)


def test_set_speed_action_sets_and_holds_the_speed(highway):
    speeds = highway.speeds("setspeed")
    assert speeds == pytest.approx(12)  # taken at time 0: already visible after reset
    xs = highway.xy("setspeed")[:, 0]
    assert xs[-1] - xs[0] == pytest.approx(12 * DURATION)


def test_set_velocity_action_on_a_car(highway):
    assert highway.speeds("setvelocity") == pytest.approx(7)
    xy = highway.xy("setvelocity")
    assert xy[-1] - xy[0] == pytest.approx([7 * DURATION, 0])


def test_set_position_action_teleports(highway):
    xy = highway.xy("teleport")
    # step 0 waits; step 1's teleport is applied when step 1 starts (visible after the first env.step)
    assert xy[0] == pytest.approx([400, 5.25])
    assert xy[1] == pytest.approx([900, 5.25])
    assert xy[2] == pytest.approx([901, 5.25])  # then it keeps driving at 5 m/s
    assert highway.track("teleport")[-1].lane_index == hw_lane_of(highway, "road1_lane2")


# --------------------------------------------------------------------------- collision avoidance


@pytest.mark.parametrize(
    "name, lead, speed, threshold",
    [("avoid", "stopped1", 10, 20), ("avoidfast", "stopped2", 15, 25), ("careful", "stopped3", 12, 18)],
    ids=["DriveAvoidingCollisions", "DriveAvoidingCollisions_fast", "interrupt_when"],
)
def test_stops_behind_a_stopped_car_instead_of_hitting_it(highway, name, lead, speed, threshold):
    speeds = highway.speeds(name)
    assert speeds[:5] == pytest.approx(speed, abs=0.1)  # lane following before the interrupt
    final, stopped = highway.track(name)[-1], highway.track(lead)[-1]
    assert final.speed == 0
    gap = stopped.x - final.x - 4.5  # bumper to bumper
    assert 0.5 < gap < threshold
    assert stopped.x == highway.track(lead)[0].x  # never touched
    assert not final.crashed


# --------------------------------------------------------------------------- pedestrians (urban_two_way)
#
# urban_two_way: lane 0 eastbound at Scenic y = -1.75, lane 1 westbound at +1.75,
# sidewalks centred at Scenic y = +-4.5 (highway-env y = -+4.5), x in [0, 600].

WALKING_PROGRAM = """
param map = 'urban_two_way'
model scenic.domains.driving.model

behavior Walk(direction, speed):
    take SetWalkingDirectionAction(direction), SetWalkingSpeedAction(speed)
    while True:
        wait

behavior Hold(action):
    take action
    while True:
        wait

behavior DirectionThenSpeed():
    take SetWalkingDirectionAction(-90 deg), SetSpeedAction(2)
    while True:
        wait

ego = new Car at network.lanes[0].centerline.pointAlongBy(50)
new Pedestrian at 300 @ 4.5, facing 45 deg, with name 'west', with behavior Walk(90 deg, 1.4)
new Pedestrian at 320 @ 4.5, facing 45 deg, with name 'north', with behavior Walk(0 deg, 1.4)
new Pedestrian at 340 @ 4.5, facing 45 deg, with name 'east', with behavior Walk(-90 deg, 1.4)
new Pedestrian at 360 @ -4.5, facing 45 deg, with name 'south', with behavior Walk(180 deg, 1.4)
new Pedestrian at 380 @ 4.5, facing 0 deg, with name 'speedkeeper', with behavior DirectionThenSpeed()
new Pedestrian at 400 @ -4.5, with name 'velocity', with behavior Hold(SetVelocityAction(0, 1.5))
wanderer = new Pedestrian on network.sidewalks[0].centerline, facing Range(0, 360) deg, with name 'wanderer',
    with behavior WalkForwardBehavior()
require 450 < wanderer.position.x < 550
"""


@pytest.fixture(scope="module", params=[0, 1, 2], ids=lambda seed: f"seed{seed}")
def walking(request):
    return run_scenario(WALKING_PROGRAM, 3, seed=request.param)


@pytest.mark.parametrize(
    "name, direction_deg, expected",
    [("west", 90, (-1, 0)), ("north", 0, (0, -1)), ("east", -90, (1, 0)), ("south", 180, (0, 1))],
)
def test_set_walking_direction_and_speed(walking, name, direction_deg, expected):
    """Scenic heading 90 deg is west (-x); Scenic north (+y) is highway-env -y."""
    xy = walking.xy(name)
    assert xy[-1] - xy[0] == pytest.approx(1.4 * 3 * np.array(expected), abs=1e-6)
    assert walking.speeds(name) == pytest.approx(1.4)
    assert walking.track(name)[-1].heading == pytest.approx(scenic_to_hw_heading(math.radians(direction_deg)))


def test_set_speed_action_keeps_a_walking_direction_set_in_the_same_step(walking):
    xy = walking.xy("speedkeeper")
    assert xy[-1] - xy[0] == pytest.approx([2 * 3, 0], abs=1e-6)


def test_set_velocity_action_on_a_pedestrian(walking):
    xy = walking.xy("velocity")
    assert xy[-1] - xy[0] == pytest.approx([0, -1.5 * 3], abs=1e-6)
    assert walking.speeds("velocity") == pytest.approx(1.5)


def test_walk_forward_behavior_walks_along_the_sidewalk(walking):
    xy = walking.xy("wanderer")
    moved = xy[-1] - xy[0]
    assert abs(moved[0]) == pytest.approx(3 * 1.0, abs=0.01)  # 1 m/s for 3 s, along the sidewalk (x)
    assert abs(moved[1]) < 0.01
    assert abs(xy[0, 1]) == pytest.approx(4.5, abs=0.3)  # on a sidewalk...
    assert np.abs(xy[:, 1] - xy[0, 1]).max() < 0.4  # ...and stays on it
    assert walking.speeds("wanderer") == pytest.approx(1.0)


def test_walk_forward_direction_is_random_per_scene():
    directions = set()
    for seed in range(6):
        run = run_scenario(WALKING_PROGRAM, 0.4, seed=seed)
        xy = run.xy("wanderer")
        directions.add(int(np.sign(xy[-1][0] - xy[0][0])))
    assert directions == {-1, 1}


# --------------------------------------------------------------------------- junctions (urban_crossroads)
#
# Four arms of two-way roads meet at the origin; each incoming lane ends 12 m from it.
# road1_lane1 comes from the east, road2_lane1 from the north, road3_lane1 from the
# west, road4_lane1 from the south. The cars go through in three waves whose paths
# do not cross: the straight ego and a right turn into the north-west corner
# (0-5 s); a right turn into the south-east corner and a left turn from the west
# (5-11 s); a left turn from the east (11-17 s).

CROSSROADS_PROGRAM = """
param map = 'urban_crossroads'
model scenic.domains.driving.model

def maneuver(start, kind):
    return [m for m in network.elements[start].maneuvers if m.type is kind][0]

def approach(m, distance):
    return new OrientedPoint following roadDirection from m.startLane.centerline.end for -distance

behavior Trajectory(m, speed):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=[m.startLane, m.connectingLane, m.endLane])
    do FollowLaneBehavior(target_speed=speed, laneToFollow=m.endLane)

behavior TurnThrough(m, speed):
    do FollowLaneBehavior(target_speed=speed, laneToFollow=m.startLane) until self in network.intersectionRegion
    do TurnBehavior(trajectory=[m.connectingLane, m.endLane], target_speed=speed)
    # TurnBehavior stops as soon as the car's front leaves the junction, before the
    # end lane starts; keep tracking the connecting lane into the end lane.
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=[m.connectingLane, m.endLane])

straight = maneuver('road4_lane1', ManeuverType.STRAIGHT)
tbRight = maneuver('road2_lane1', ManeuverType.RIGHT_TURN)
ftRight = maneuver('road4_lane1', ManeuverType.RIGHT_TURN)
ftLeft = maneuver('road3_lane1', ManeuverType.LEFT_TURN)
tbLeft = maneuver('road1_lane1', ManeuverType.LEFT_TURN)

ego = new Car at approach(straight, 30), with speed 10, with behavior FollowLaneBehavior(target_speed=10)
new Car at approach(tbRight, 20), with name 'tbright', with speed 6, with behavior TurnThrough(tbRight, 6)
new Car at approach(ftRight, 55), with name 'ftright', with speed 8, with behavior Trajectory(ftRight, 8)
new Car at approach(ftLeft, 60), with name 'ftleft', with speed 8, with behavior Trajectory(ftLeft, 8)
new Car at approach(tbLeft, 70), with name 'tbleft', with speed 6, with behavior TurnThrough(tbLeft, 6)
"""

CROSSROADS_CARS = {
    # name: (start lane, maneuver type)
    "ego": ("road4_lane1", ManeuverType.STRAIGHT),
    "tbright": ("road2_lane1", ManeuverType.RIGHT_TURN),
    "ftright": ("road4_lane1", ManeuverType.RIGHT_TURN),
    "ftleft": ("road3_lane1", ManeuverType.LEFT_TURN),
    "tbleft": ("road1_lane1", ManeuverType.LEFT_TURN),
}


@pytest.fixture(scope="module")
def crossroads():
    return run_scenario(CROSSROADS_PROGRAM, 18)


def _maneuver(start, kind):
    network = load_road_network(resolve_map("urban_crossroads")).scenic_network
    return next(m for m in network.elements[start].maneuvers if m.type is kind)


@pytest.mark.slow
def test_crossroads_program_has_no_collisions(crossroads):
    assert crossroads.events("collision") == []
    assert not any(info["off_road"] for info in crossroads.infos)


@pytest.mark.parametrize("name", list(CROSSROADS_CARS))
def test_junction_maneuver_ends_on_its_end_lane(crossroads, name):
    """FollowLaneBehavior goes straight; FollowTrajectory and Turn behaviours take their turn."""
    start, kind = CROSSROADS_CARS[name]
    m = _maneuver(start, kind)
    track = crossroads.track(name)
    visited = {s.lane_index for s in track}
    assert hw_lane_of(crossroads, m.connectingLane.uid) in visited
    final = track[-1]
    assert final.lane_index == hw_lane_of(crossroads, m.endLane.uid)
    end_lane = converted_network(crossroads).hw_lane(m.endLane.uid)
    s, lat = end_lane.local_coordinates(final.position)
    assert s > 5 and abs(lat) < 0.2
    assert abs(wrap(final.heading - end_lane.heading_at(s))) < math.radians(3)
    # turned the right way: left turns are counter-clockwise (the Scenic heading grows by 90 deg)
    turned = wrap(scenic_heading(final.heading) - scenic_heading(track[0].heading))
    expected = {ManeuverType.STRAIGHT: 0, ManeuverType.LEFT_TURN: math.pi / 2, ManeuverType.RIGHT_TURN: -math.pi / 2}
    assert turned == pytest.approx(expected[kind], abs=0.05)


@pytest.mark.parametrize("name", list(CROSSROADS_CARS))
def test_junction_maneuver_stays_in_lane(crossroads, name):
    errors = lateral_errors(crossroads, name)
    assert errors.max() < 1.0
    assert np.median(errors) < 0.05


def test_follow_lane_keeps_its_speed_straight_through(crossroads):
    assert np.abs(crossroads.speeds("ego")[5:] - 10).max() < 0.3


# --------------------------------------------------------------------------- Town01 junctions


def _town01_junction_approaches(count):
    """Town01 lanes ending at a junction after a long straight, spread over the map."""
    converted = load_road_network(TOWN01)
    lanes = sorted(
        (
            lane
            for lane in converted.scenic_network.lanes
            if lane.centerline.length > 40
            and any(m.connectingLane is not None and converted.is_connecting(m.connectingLane.uid) for m in lane.maneuvers)
        ),
        key=lambda lane: lane.uid,
    )
    step = len(lanes) // count
    return [lanes[i * step].uid for i in range(count)]


# three approaches, chosen when the module's first junction test runs: loading Town01 at import would
# make every collection of the suite parse the map
TOWN01_APPROACHES = 3


@pytest.fixture(scope="module")
def town01_starts():
    return _town01_junction_approaches(TOWN01_APPROACHES)


@pytest.fixture(scope="module")
def town01_junctions(town01_starts):
    cars = "\n".join(
        f"new Car following roadDirection from network.elements['{uid}'].centerline.end for -25, "
        f"with name 'car{i}', with speed 8, with behavior FollowLaneBehavior(target_speed=8)"
        for i, uid in enumerate(town01_starts)
    )
    source = f"""
param map = r'{TOWN01}'
model scenic.domains.driving.model
ego = new Car at network.lanes[0].centerline.pointAlongBy(1), with speed 0
{cars}
"""
    return run_scenario(source, 10)


@pytest.mark.slow
@pytest.mark.parametrize("index", range(TOWN01_APPROACHES))
def test_follow_lane_through_a_town01_junction(town01_junctions, town01_starts, index):
    run, name = town01_junctions, f"car{index}"
    converted = converted_network(run)
    lane = converted.scenic_network.elements[town01_starts[index]]
    allowed_ends = {m.endLane.uid for m in lane.maneuvers}
    track = run.track(name)
    assert any(s.lane_index and converted.is_connecting(s.lane_index) for s in track), "never entered the junction"
    final = track[-1]
    _, final_lane, _ = lane_offset(converted, final.x, final.y, final.heading)
    assert converted.scenic_lane_of[final_lane] in allowed_ends
    errors = lateral_errors(run, name)
    assert errors.max() < 0.8
    assert errors[-5:].max() < 0.2
    assert run.events("collision") == []
