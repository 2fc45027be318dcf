"""CARLA- and MetaDrive-model scripts run unchanged in DV2S-v0 (envs/scenic_highway/carla, .../metadrive).

Each script in tests/data/carla_model is written as for Scenic 3.1.1's CARLA (or
MetaDrive) model and run through ``gym.make("dv2s_gym:DV2S-v0", scenario=PATH)``; it is
copied next to a copy of Town01.xodr because the safety check only takes map paths
relative to the script.
"""

from __future__ import annotations

import math
import shutil
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from envs.errors import ForeignConstructWarning, UnsupportedConstructError
from envs.scenarios import FOREIGN_MODELS, MODEL, model_for

pytestmark = pytest.mark.usefixtures("in_process_simulator")

DATA = Path(__file__).parent / "data" / "carla_model"
TOWN01 = Path(__file__).parent / "data" / "maps" / "CARLA" / "Town01.xodr"
IDLE = 1


@pytest.fixture
def script(tmp_path):
    """Copy a script of tests/data/carla_model next to Town01.xodr; returns its path."""
    shutil.copy(TOWN01, tmp_path / "Town01.xodr")

    def _copy(name: str) -> str:
        target = tmp_path / f"{name}.scenic"
        shutil.copy(DATA / f"{name}.scenic", target)
        return str(target)

    return _copy


def _run(path: str, steps: int, seed: int = 0):
    env = gym.make("dv2s_gym:DV2S-v0", scenario=path)
    env.reset(seed=seed)
    unwrapped = env.unwrapped
    infos = []
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(IDLE)
        infos.append(info)
        if terminated or truncated:
            break
    return env, unwrapped, infos


def _actors(unwrapped):
    return {getattr(v, "name", None): v for v in list(unwrapped.road.vehicles) + list(unwrapped.road.objects)}


def test_model_lines_route_to_the_facades():
    assert model_for("param map = 'x'\nmodel scenic.simulators.carla.model\n") == FOREIGN_MODELS["carla"]
    assert model_for("model scenic.simulators.metadrive.model\n") == FOREIGN_MODELS["metadrive"]
    assert model_for("model scenic.domains.driving.model\n") == MODEL


@pytest.mark.slow
def test_blueprints_choose_kind_and_size_and_cosmetics_are_accepted(script):
    env, unwrapped, _ = _run(script("props_and_blueprints"), steps=3)
    kinds = unwrapped.trace.kinds
    actors = _actors(unwrapped)
    # a Car with a fire-truck blueprint becomes a truck of the blueprint's size
    assert kinds["Car1"] == "truck"
    assert actors["Car1"].LENGTH > 7.5 and actors["Car1"].WIDTH > 2.5
    assert kinds["Bicycle1"] == "bicycle" and actors["Bicycle1"].LENGTH < 2.5
    assert kinds["Pedestrian1"] == "pedestrian"
    assert kinds["Cone1"] == "obstacle" and actors["Cone1"].LENGTH < 1.0
    # color and rolename on the ego were accepted: the tesla keeps its blueprint length
    assert 4.5 < actors["ego"].LENGTH < 5.0
    env.close()


@pytest.mark.slow
def test_props_are_static_obstacles_that_collide(script):
    env, unwrapped, infos = _run(script("prop_collision"), steps=30)
    assert unwrapped.trace.kinds["Barrier1"] == "obstacle"
    assert infos[-1]["crashed"]
    assert "Barrier1" in infos[-1]["collisions"]
    barrier = [state["Barrier1"] for state in unwrapped.trace.states]
    assert barrier[0][:2] == barrier[-1][:2]  # it never moved
    env.close()


@pytest.mark.slow
def test_autopilot_cars_follow_their_lane(script):
    env = gym.make("dv2s_gym:DV2S-v0", scenario=script("autopilot"))
    env.reset(seed=0)
    unwrapped = env.unwrapped
    assert unwrapped.trace.kinds["Car1"] == "car"
    offsets = []
    for _ in range(40):
        _, _, terminated, truncated, _ = env.step(IDLE)
        npc = _actors(unwrapped)["Car1"]
        _, lateral = npc.lane.local_coordinates(npc.position)
        offsets.append(abs(lateral))
        if terminated or truncated:
            break
    positions = [np.array(state["Car1"][:2]) for state in unwrapped.trace.states]
    travelled = sum(float(np.linalg.norm(b - a)) for a, b in zip(positions, positions[1:]))
    assert travelled > 20.0  # the autopilot drives (CARLA's Traffic Manager would too)
    assert max(offsets) < 1.0  # ... in its lane
    env.close()


@pytest.mark.slow
def test_crossing_pedestrian_crosses_ahead_of_the_ego(script):
    env, unwrapped, _ = _run(script("crossing"), steps=30)
    states = unwrapped.trace.states
    heading = states[0]["ego"][2]
    forward = np.array([math.cos(heading), math.sin(heading)])
    start, end = np.array(states[0]["Pedestrian1"][:2]), np.array(states[-1]["Pedestrian1"][:2])
    moved = end - start
    across = abs(forward[0] * moved[1] - forward[1] * moved[0])
    assert across > 3.0  # walked across the ego's path
    assert abs(float(moved @ forward)) < 1.0  # not along it
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_visible_and_view_region_work_in_2d(script, seed):
    env, unwrapped, _ = _run(script("visibility"), steps=1, seed=seed)
    state = unwrapped.trace.states[0]
    ego, cone = np.array(state["ego"][:2]), np.array(state["Cone1"][:2])
    offset = cone - ego
    assert np.linalg.norm(offset) <= 30.5  # visibleDistance 30
    heading = state["ego"][2]
    bearing = math.atan2(offset[1], offset[0]) - heading
    bearing = (bearing + math.pi) % (2 * math.pi) - math.pi
    assert abs(math.degrees(bearing)) <= 31.0  # viewAngle 60 deg
    env.close()


@pytest.mark.slow
def test_traffic_light_helpers_and_gears_warn_and_do_nothing(script):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env, unwrapped, _ = _run(script("traffic_lights_and_gears"), steps=20)
    foreign = [str(w.message) for w in caught if issubclass(w.category, ForeignConstructWarning)]
    lights = [m for m in foreign if "traffic lights are not simulated" in m]
    assert len(lights) == 1  # one warning per scenario, although the helpers run every step
    assert any("SetGearAction" in m for m in foreign)
    assert any("SetVehicleLightStateAction" in m for m in foreign)
    # no light is ever near: the car drove on (throttle) instead of braking
    assert unwrapped.trace.states[-1]["Car1"][3] > 1.0
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, construct",
    [("unsupported_waypoints", "TrackWaypointsAction"), ("unsupported_autopilot_action", "SetAutopilotAction")],
)
def test_unsupported_carla_actions_name_the_construct(script, name, construct):
    with pytest.raises(UnsupportedConstructError) as info:
        _run(script(name), steps=5)
    message = str(info.value)
    assert f"`{construct}`" in message and "\n" not in message


@pytest.mark.slow
def test_metadrive_script_runs_with_sumo_map_param(script):
    env, unwrapped, _ = _run(script("metadrive_follow"), steps=15)
    assert unwrapped.trace.kinds["Car1"] == "car"
    assert unwrapped.trace.kinds["Pedestrian1"] == "pedestrian"
    first, last = unwrapped.trace.states[0]["Car1"], unwrapped.trace.states[-1]["Car1"]
    assert math.dist(first[:2], last[:2]) > 5.0
    env.close()


@pytest.mark.slow
def test_road_id_of_another_map_is_named():
    from envs.errors import ScenarioCompileError
    from envs.scenarios import compile_scenario

    source = (
        "param map = 'highway_straight'\nmodel scenic.simulators.carla.model\n"
        "section = network.elements['road999'].sections[0]\nego = new Car\n"
    )
    with pytest.raises(ScenarioCompileError, match="no element `road999`"):
        compile_scenario(source, name="foreign_road_id")
