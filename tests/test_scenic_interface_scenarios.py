"""The Scenic simulator interface for highway-env: scenario-level features.

Requirements and termination (``require``, ``require always``, ``terminate
when``/``after``, monitors), the kinds of actors (trucks, obstacles, pedestrians
that collide and are observed), VerifAI external parameters, scripts written for
CARLA or MetaDrive, whole CARLA towns, and who drives the ego (``ego_policy``).
Each test runs a small Scenic program in ``DV2SEnv`` and asserts on highway-env
state (highway-env frame: ``y`` is the negated Scenic ``y``) or on the episode's
info. ``test_scenic_interface.py`` covers the behaviour library and the actions.

Compiling a program takes about 3 s, so programs are shared by the tests that
can use them (module-scoped fixtures).
"""

from __future__ import annotations

import numpy as np
import pytest

import scenic  # noqa: F401  (a core dependency: a broken install fails here)

from envs.errors import UnsupportedConstructError  # noqa: E402
from scenic_sim_helpers import (  # noqa: E402
    TOWN01,
    TOWN02,
    converted_network,
    lane_offset,
    lateral_errors,
    make_env,
    run_scenario,
)

pytestmark = pytest.mark.usefixtures("in_process_simulator")

# DiscreteMetaAction
IDLE, FASTER = 1, 3

# highway_straight: four lanes along +x; Scenic lane i is centred at highway-env y = 12.25 - 3.5 i.


def _accelerating_ego(extra: str, model: str = "scenic.domains.driving.model") -> str:
    """An ego at full throttle (5 m/s^2) from 2 m/s, x = 50, plus ``extra`` statements."""
    return f"""
param map = 'highway_straight'
model {model}
behavior Accelerate():
    while True:
        take SetThrottleAction(1.0)
ego = new Car at network.lanes[1].centerline.pointAlongBy(50), with speed 2, with behavior Accelerate()
{extra}
"""


# --------------------------------------------------------------------------- require always, termination


@pytest.mark.slow
def test_require_always_violated_mid_run_truncates_as_rejected():
    run = run_scenario(_accelerating_ego("require always ego.speed < 8"), 5)
    assert run.truncated and not run.terminated
    info = run.final_info
    assert info["scenic_status"] == "rejected"
    assert "ego.speed < 8" in info["scenic_reason"] or info["scenic_reason"]
    # from 2 m/s at 5 m/s^2 the speed passes 8 m/s after 1.2 s
    assert run.duration == pytest.approx(1.2, abs=0.21)
    speeds = run.speeds("ego")
    assert speeds[-2] < 8 <= speeds[-1]
    assert [e["kind"] for e in run.events() if e["kind"].startswith("scenic_")] == ["scenic_rejected"]


def test_terminate_when_ends_the_episode_as_finished():
    run = run_scenario(_accelerating_ego("terminate when ego.position.x > 60"), 10)
    assert run.terminated and not run.truncated
    assert run.final_info["scenic_status"] == "finished"
    xs = run.xy("ego")[:, 0]
    assert xs[-1] > 60 >= xs[-2]  # ends at the first step where the condition holds
    assert [e["kind"] for e in run.events() if e["kind"].startswith("scenic_")] == ["scenic_finished"]


def test_monitor_that_terminates():
    extra = """
monitor StopWhenPast(limit):
    while True:
        if ego.position.x > limit:
            terminate
        wait
require monitor StopWhenPast(58)
"""
    run = run_scenario(_accelerating_ego(extra), 10)
    assert run.terminated and not run.truncated
    assert run.final_info["scenic_status"] == "finished"
    xs = run.xy("ego")[:, 0]
    assert xs[-1] > 58 and run.duration < 2.5


@pytest.fixture(scope="module")
def metadrive_terminate_after():
    """``terminate after``, in a script written for MetaDrive (runs with our model)."""
    extra = """
other = new Car at network.lanes[2].centerline.pointAlongBy(70), with speed 8,
    with behavior FollowLaneBehavior(target_speed=8)
terminate after 3 seconds
"""
    return run_scenario(_accelerating_ego(extra, model="scenic.simulators.metadrive.model"), 10)


def test_terminate_after_seconds(metadrive_terminate_after):
    run = metadrive_terminate_after
    assert run.terminated and not run.truncated
    assert run.final_info["scenic_status"] == "finished"
    assert run.duration == pytest.approx(3.0, abs=0.21)


# --------------------------------------------------------------------------- kinds of actors, require

KINDS_PROGRAM = """
param map = 'highway_straight'
model scenic.domains.driving.model
gap = Range(0, 100)
param truckGap = gap
require gap > 60
ego = new Car at network.lanes[1].centerline.pointAlongBy(50), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
box = new Obstacle at network.lanes[1].centerline.pointAlongBy(80), with width 3, with length 1
truckStart = network.lanes[3].centerline.pointAlongBy(50)
truck = new Truck following roadDirection from truckStart for gap, with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
"""


@pytest.fixture(scope="module")
def kinds():
    return run_scenario(KINDS_PROGRAM, 4)


def test_require_rejects_scenes_that_violate_it():
    env = make_env(KINDS_PROGRAM, 1)
    try:
        for seed in range(5):
            _, info = env.reset(seed=seed)
            assert 60 < info["params"]["truckGap"] <= 100
            truck = next(v for v in env.unwrapped.road.vehicles if v.name == "Truck1")
            assert truck.position[0] == pytest.approx(50 + info["params"]["truckGap"])
    finally:
        env.close()


def test_truck_is_longer_and_wider_than_a_car(kinds):
    assert kinds.hw_sizes["Truck1"] == pytest.approx((9.0, 2.5))
    assert kinds.hw_sizes["ego"] == pytest.approx((4.5, 2.0), abs=0.3)
    assert kinds.hw_kinds["Truck1"] == "Truck"
    xs = kinds.xy("Truck1")[:, 0]
    assert xs[-1] - xs[0] == pytest.approx(40, abs=0.5)  # it drives at 10 m/s


def test_obstacle_blocks_the_lane_and_a_car_hitting_it_collides(kinds):
    collisions = kinds.events("collision")
    assert [sorted(e["actors"]) for e in collisions] == [["Obstacle1", "ego"]]
    # front bumper (x + 2.25) reaches the box's face (80 - 0.5) after about 2.7 s
    assert collisions[0]["time"] == pytest.approx((80 - 0.5 - 2.25 - 50) / 10, abs=0.15)
    info = kinds.final_info
    assert info["collisions"] == ["Obstacle1"] and info["crashed"]
    assert kinds.xy("ego")[:, 0].max() + 2.25 < 80 + 0.5  # it does not drive through
    assert kinds.hw_types["Obstacle1"] == "Prop"
    box = kinds.xy("Obstacle1")
    assert np.abs(box - [80, 8.75]).max() < 1e-9  # static, even when hit


# --------------------------------------------------------------------------- pedestrians

PEDESTRIAN_PROGRAM = """
param map = 'urban_two_way'
model scenic.domains.driving.model
behavior Cross():
    take SetWalkingDirectionAction(0 deg), SetWalkingSpeedAction(1.5)
    while True:
        wait
ego = new Car at network.lanes[0].centerline.pointAlongBy(100), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
walker = new Pedestrian at 122 @ -4.5, facing 0 deg, with behavior Cross()
"""


@pytest.fixture(scope="module")
def pedestrian_hit():
    """A car at 10 m/s and a pedestrian stepping into its lane 22 m ahead."""
    config = {
        "observation": {
            "type": "Kinematics",
            "vehicles_count": 5,
            "features": ["presence", "x", "y", "vx", "vy"],
            "absolute": False,
            "normalize": False,
            "see_behind": True,
        }
    }
    return run_scenario(PEDESTRIAN_PROGRAM, 4, config=config, observe=True)


def test_car_hitting_a_pedestrian_is_a_collision_naming_both(pedestrian_hit):
    run = pedestrian_hit
    collisions = run.events("collision")
    assert [sorted(e["actors"]) for e in collisions] == [["Pedestrian1", "ego"]]
    assert 1.2 < collisions[0]["time"] < 2.4
    assert run.final_info["collisions"] == ["Pedestrian1"]
    assert run.final_info["crashed"]
    hit = next(i for i, info in enumerate(run.infos) if any(e["kind"] == "collision" for e in info["events"]))
    walker, ego = run.states[hit]["Pedestrian1"], run.states[hit]["ego"]
    assert abs(walker.y - ego.y) < 1.5 and 0 < walker.x - ego.x < 3
    assert walker.crashed and ego.crashed


def test_pedestrian_appears_in_the_kinematics_observation(pedestrian_hit):
    run = pedestrian_hit
    for step in (0, 3, 6):
        obs = run.observations[step]
        ego, walker = run.states[step]["ego"], run.states[step]["Pedestrian1"]
        rows = obs[obs[:, 0] == 1]
        assert len(rows) == 2  # the ego's own row, then the pedestrian
        assert rows[1][1:3] == pytest.approx([walker.x - ego.x, walker.y - ego.y], abs=1e-3)
    # walking north (Scenic +y, highway-env -y) at 1.5 m/s; relative to the ego driving +x at 10 m/s
    assert run.observations[3][1][3:5] == pytest.approx([-10, -1.5], abs=0.05)


# --------------------------------------------------------------------------- VerifAI


VERIFAI_PROGRAM = """
param verifaiSamplerType = 'halton'
from scenic.core.external_params import VerifaiRange, VerifaiDiscreteRange

param gap = VerifaiRange(10, 40)
param leadLane = VerifaiDiscreteRange(0, 3)
param map = 'highway_straight'
model scenic.domains.driving.model
ego = new Car at network.lanes[1].centerline.pointAlongBy(100), with speed 10
lead = new Car following roadDirection from ego for globalParameters.gap
"""


def test_verifai_external_parameters_sample_in_range():
    pytest.importorskip("verifai")
    env = make_env(VERIFAI_PROGRAM, 0.4)
    gaps, lanes = [], []
    try:
        for seed in range(5):
            _, info = env.reset(seed=seed)
            gap, lane = info["params"]["gap"], info["params"]["leadLane"]
            assert 10 <= gap <= 40
            assert lane in (0, 1, 2, 3)
            vehicles = {v.name: v for v in env.unwrapped.road.vehicles}
            assert vehicles["Car1"].position[0] - vehicles["ego"].position[0] == pytest.approx(gap, abs=1e-6)
            gaps.append(gap)
            lanes.append(lane)
            env.step(IDLE)
    finally:
        env.close()
    assert len(set(gaps)) == 5  # a new sample every episode
    assert len(set(lanes)) > 1


# --------------------------------------------------------------------------- who drives the ego; CARLA scripts

EGO_POLICY_PROGRAM = """
param map = 'highway_straight'
model scenic.simulators.carla.model
behavior SlamBrakes():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)
ego = new Car at network.lanes[1].centerline.pointAlongBy(50), with speed 20, with behavior SlamBrakes()
other = new Car at network.lanes[2].centerline.pointAlongBy(50), with speed 10,
    with behavior FollowLaneBehavior(target_speed=10)
walker = new Pedestrian at 100 @ -1.75, facing 90 deg, with regionContainedIn None
"""


@pytest.mark.slow
def test_agent_drives_the_ego_and_its_scenic_behavior_is_ignored():
    run = run_scenario(EGO_POLICY_PROGRAM, 3, config={"ego_policy": "agent"}, action=IDLE)
    assert run.hw_types["ego"] == "MDPVehicle"
    assert run.speeds("ego").min() == pytest.approx(20, abs=0.1)  # IDLE keeps 20 m/s: no braking
    assert run.xy("ego")[-1][0] - run.xy("ego")[0][0] == pytest.approx(60, abs=1)
    # the other agents still run their behaviours
    assert run.xy("Car1")[-1][0] - run.xy("Car1")[0][0] == pytest.approx(30, abs=0.5)


@pytest.mark.slow
@pytest.mark.parametrize("action", [IDLE, FASTER], ids=["IDLE", "FASTER"])
def test_scenic_ego_policy_runs_the_ego_behavior_and_ignores_actions(action):
    run = run_scenario(EGO_POLICY_PROGRAM, 3, config={"ego_policy": "scenic"}, action=action)
    assert run.hw_types["ego"] == "ScenicVehicle"
    speeds = run.speeds("ego")
    assert speeds[0] == 20 and speeds[-1] == 0
    assert run.xy("Car1")[-1][0] - run.xy("Car1")[0][0] == pytest.approx(30, abs=0.5)


@pytest.mark.parametrize("which", ["carla", "metadrive"])
def test_script_for_another_simulator_runs_with_our_model(which, metadrive_terminate_after):
    """Scripts whose ``model`` line names CARLA or MetaDrive run with the highway-env model."""
    if which == "carla":
        run = run_scenario(EGO_POLICY_PROGRAM, 2)
        assert set(run.states[-1]) == {"ego", "Car1", "Pedestrian1"}
        assert run.hw_types["Pedestrian1"] == "Pedestrian"
    else:
        run = metadrive_terminate_after
        assert set(run.states[-1]) == {"ego", "Car1"}
    assert run.hw_types["ego"] == run.hw_types["Car1"] == "ScenicVehicle"
    car = run.xy("Car1")
    assert car[-1][0] - car[0][0] == pytest.approx(run.speeds("Car1")[0] * run.duration, rel=0.02)
    assert not run.final_info["crashed"]


CARLA_HEADER = "param map = 'highway_straight'\nmodel scenic.simulators.carla.model\n"


@pytest.mark.parametrize(
    "construct, body",
    [
        # blueprint, AutopilotBehavior and props run since the CARLA-model façade (tests/test_carla_model.py)
        ("carlaActor", "behavior Peek():\n    actor = self.carlaActor\n    wait\nego = new Car with behavior Peek()\n"),
        ("SetJumpAction", "behavior Jump():\n    take SetJumpAction(True)\nego = new Car\nw = new Pedestrian ahead of ego by 10, with regionContainedIn None, with behavior Jump()\n"),
        ("TrackWaypointsAction", "behavior Track():\n    take TrackWaypointsAction([self.position])\nego = new Car with behavior Track()\n"),
    ],
)
def test_carla_only_construct_is_reported_by_name(construct, body):
    with pytest.raises(UnsupportedConstructError, match=f"`{construct}`"):
        run_scenario(CARLA_HEADER + body, 0.4)


# --------------------------------------------------------------------------- CARLA towns

TOWN_PROGRAM = """
param map = r'{town}'
model scenic.domains.driving.model
ego = new Car on Uniform(*network.lanes).centerline, with speed 5,
    with behavior FollowLaneBehavior(target_speed=8)
require (distance from ego to intersection) > 10
for i in range(3):
    npc = new Car on Uniform(*network.lanes).centerline, with speed 5,
        with behavior DriveAvoidingCollisions(target_speed=8, avoidance_threshold=12)
    require (distance from npc to ego) > 15
"""


@pytest.mark.slow
@pytest.mark.parametrize("town", [TOWN01, TOWN02], ids=["Town01", "Town02"])
def test_town_scene_with_npcs_runs_20_seconds(town):
    run = run_scenario(TOWN_PROGRAM.format(town=town), 20, seed=3)
    assert run.truncated and not run.terminated
    assert run.duration == pytest.approx(20)
    assert set(run.states[-1]) == {"ego", "Car1", "Car2", "Car3"}
    assert not any(info["off_road"] for info in run.infos)
    xy = run.xy("ego")
    assert np.hypot(*(xy[-1] - xy[0])) > 100  # it drove, through at least one junction or corner
    errors = lateral_errors(run)
    assert errors.max() < 1.0  # in its lane throughout
    converted = converted_network(run)
    for name in ("Car1", "Car2", "Car3"):
        final = run.track(name)[-1]
        assert abs(lane_offset(converted, final.x, final.y, final.heading)[0]) < 1.5
