"""Environment-level tests of ``DV2S-v0``: API conformance, scenario selection,
determinism, termination, vector envs, rendering and reset memory.

Compiling a scenario takes about a second and is cached per process by
``envs.scenarios``, so every test builds its own env cheaply; episodes use
short ``duration`` configs.
"""

from __future__ import annotations

import functools
import math
import os
import shutil
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import dv2s_gym  # noqa: E402,F401  (registers DV2S-v0)
from envs.dv2s_env import DV2SEnv, resolve_scenarios  # noqa: E402
from scenario_bank import BANK_DIR, list_scenarios, scenario_metadata  # noqa: E402

BRAKES = "highway_lead_vehicle_brakes"
PULL_BACK_IN = "urban_pull_back_in"
PEDESTRIAN = "urban_pedestrian_crossing"
PAPER_USE_CASES = [
    BRAKES,
    "highway_onramp_insertion",
    "urban_left_turn_oncoming",
    PEDESTRIAN,
    PULL_BACK_IN,
]

# DiscreteMetaAction
LANE_LEFT, IDLE, FASTER, SLOWER = 0, 1, 3, 4

EGO_COLOR = (50, 200, 0)
PEDESTRIAN_COLOR = (255, 140, 0)


def make(scenario=BRAKES, render_mode=None, **config) -> DV2SEnv:
    config.setdefault("duration", 2.0)
    return DV2SEnv(scenario=scenario, config=config, render_mode=render_mode)


def rollout(env, seed, actions):
    """Reset with ``seed`` and apply ``actions`` until the episode ends; list of step tuples."""
    obs, info = env.reset(seed=seed)
    steps = [(obs, None, False, False, info)]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        steps.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return steps


def assert_same_steps(a, b):
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert np.array_equal(x[0], y[0]), f"observations differ at step {i}"
        assert x[1:] == y[1:], f"reward/termination/info differ at step {i}"


def pixels_of(frame: np.ndarray, color) -> int:
    return int(np.all(frame == np.asarray(color, dtype=np.uint8), axis=-1).sum())


@pytest.fixture(scope="module", autouse=True)
def _compiled_bank():
    """Compile the scenarios used here once for the module (later envs hit the cache)."""
    for name in (BRAKES, PULL_BACK_IN, PEDESTRIAN):
        DV2SEnv(scenario=name, config={"duration": 1.0}).close()


# --------------------------------------------------------------------------- API


def _unexpected(caught, allowed):
    """Messages of the user warnings caught, but the ``allowed`` ones."""
    return [
        str(w.message)
        for w in caught
        if issubclass(w.category, UserWarning) and not any(a in str(w.message) for a in allowed)
    ]


@pytest.mark.slow
def test_a_misspelt_config_key_is_refused_with_a_suggestion():
    from envs.errors import UnknownConfigKeyError

    with pytest.raises(UnknownConfigKeyError, match=r"'duraton' \(did you mean 'duration'\?\)"):
        DV2SEnv(scenario=BRAKES, config={"duraton": 3.0})


@pytest.mark.parametrize("config, message", [
    ({"observation": {"type": "Kinematic"}}, r"unknown observation type 'Kinematic' \(did you mean 'Kinematics'\?\); "
                                             r"DV2S-v0 supports Kinematics, OccupancyGrid"),
    ({"action": {"type": "Continuous"}}, r"unknown action type 'Continuous' \(did you mean 'ContinuousAction'\?\); "
                                         r"DV2S-v0 supports DiscreteMetaAction, ContinuousAction, DiscreteAction"),
    ({"observation": "Kinematics"}, r"config\['observation'\] must be a dict with a 'type'"),
    ({"observation": {"type": "GrayscaleObservation", "stack_size": 4}},
     r"the GrayscaleObservation observation needs 'observation_shape', 'weights'; e.g. config\['observation'\] = "),
])
def test_an_unknown_observation_or_action_type_is_named_with_the_choices(config, message):
    from envs.errors import UnknownConfigKeyError

    with pytest.raises(UnknownConfigKeyError, match=message):
        DV2SEnv(scenario=BRAKES, config=config)
    text = (ROOT / "scenario_bank" / "scenarios" / BRAKES / "scenario.scenic").read_text()
    with pytest.raises(UnknownConfigKeyError, match=message):  # Scenic text: checked before anything runs
        gym.make("dv2s_gym:DV2S-v0", scenario=text, config=config)


def test_gymnasium_env_checker_passes():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("DV2S-v0", scenario=BRAKES, config={"duration": 2.0})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    # Kinematics observations are unbounded in highway-env; anything else is a finding.
    allowed = ("minimum value is -infinity", "maximum value is infinity")
    assert _unexpected(caught, allowed) == []
    env.close()


def test_sb3_env_checker_passes():
    from stable_baselines3.common.env_checker import check_env

    env = make()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, warn=True)
    assert _unexpected(caught, ("unconventional shape",)) == []
    env.close()


@pytest.mark.parametrize(
    "action, space",
    [
        ({"type": "DiscreteMetaAction"}, gym.spaces.Discrete),
        ({"type": "ContinuousAction"}, gym.spaces.Box),
        ({"type": "DiscreteAction", "actions_per_axis": 3}, gym.spaces.Discrete),
    ],
    ids=["DiscreteMetaAction", "ContinuousAction", "DiscreteAction"],
)
def test_action_types_step(action, space):
    env = make(action=action)
    assert isinstance(env.action_space, space)
    env.action_space.seed(0)
    obs, _ = env.reset(seed=1)
    for _ in range(4):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert 0.0 <= reward <= 1.0
        if terminated or truncated:
            break
    env.close()


def test_continuous_action_drives_the_ego():
    """Full throttle ends faster than full brake from the same scene."""
    speeds = {}
    for throttle in (1.0, -1.0):
        env = make(action={"type": "ContinuousAction"})
        env.reset(seed=3)
        for _ in range(3):
            env.step(np.array([throttle, 0.0], dtype=np.float32))
        speeds[throttle] = env.vehicle.speed
        env.close()
    assert speeds[1.0] > speeds[-1.0] + 5.0


@pytest.mark.parametrize(
    "observation",
    [
        {"type": "Kinematics"},
        {"type": "OccupancyGrid"},
        {"type": "TimeToCollision", "horizon": 5},
        {
            "type": "GrayscaleObservation",
            "observation_shape": (84, 84),
            "stack_size": 4,
            "weights": [0.2989, 0.5870, 0.1140],
            "scaling": 1.75,
        },
    ],
    ids=lambda o: o["type"],
)
def test_observation_types(observation):
    env = make(observation=observation)
    obs, _ = env.reset(seed=2)
    assert obs.shape == env.observation_space.shape
    assert env.observation_space.contains(obs)
    for _ in range(3):
        obs, *_ = env.step(IDLE)
        assert env.observation_space.contains(obs)
    if observation["type"] == "OccupancyGrid":
        assert obs[0].sum() >= 1  # the presence layer sees the ego's neighbours
    if observation["type"] == "GrayscaleObservation":
        assert obs.dtype == np.uint8 and obs[-1].std() > 0  # a drawn road, not a blank image
    if observation["type"] == "Kinematics":
        assert obs[0, 0] == 1 and obs[1:, 0].sum() >= 1  # the ego and at least one other car
    env.close()


# ---------------------------------------------------------------- scenario specs


def _info_keys_ok(info, scenario):
    assert info["scenario"] == scenario
    assert isinstance(info["scene_seed"], int)
    assert isinstance(info["params"], dict)
    assert "map" in info["params"]


def test_bank_name_and_info():
    env = gym.make("DV2S-v0", scenario=BRAKES, config={"duration": 1.0})
    _, info = env.reset(seed=5)
    _info_keys_ok(info, BRAKES)
    assert info["seed"] == 5
    assert info["params"]["map"].endswith("highway_straight.xodr")
    assert 20 <= info["params"]["ego_speed"] <= 28
    assert 18 <= info["params"]["lead_gap"] <= 35
    assert info["action"] is None
    _, _, _, _, step_info = env.step(IDLE)
    assert {k: step_info[k] for k in ("scenario", "seed", "scene_seed", "params")} == {
        k: info[k] for k in ("scenario", "seed", "scene_seed", "params")
    }
    env.close()


def test_path_to_scenic_file(tmp_path):
    script = tmp_path / "my_brakes.scenic"
    script.write_text((BANK_DIR / BRAKES / "scenario.scenic").read_text())
    env = gym.make("DV2S-v0", scenario=str(script), config={"duration": 1.0})
    _, info = env.reset(seed=0)
    _info_keys_ok(info, "my_brakes")
    env.step(IDLE)
    env.close()
    env = gym.make("DV2S-v0", scenario=script, config={"duration": 1.0})  # a Path works too
    assert env.reset(seed=0)[1]["scenario"] == "my_brakes"
    env.close()


@pytest.mark.slow
def test_scenic_source_text():
    source = textwrap.dedent(
        """
        param map = 'highway_straight'
        model scenic.domains.driving.model
        param gap = Range(15, 25)
        ego = new Car with speed 20
        lead = new Car following roadDirection from ego for globalParameters.gap, with speed 15
        """
    )
    env = gym.make("DV2S-v0", scenario=source, config={"duration": 1.0})
    obs, info = env.reset(seed=0)
    _info_keys_ok(info, "<string>")
    assert 15 <= info["params"]["gap"] <= 25
    assert obs[:, 0].tolist().count(1) == 2  # the ego and the lead car, and nobody else
    env.step(IDLE)
    env.close()


@pytest.mark.slow
def test_list_of_names_and_tags():
    from scenario_bank import list_scenarios as names_with

    pedestrians = set(names_with(tag="pedestrian"))
    assert PEDESTRIAN in pedestrians and BRAKES not in pedestrians
    env = gym.make("DV2S-v0", scenario=[BRAKES, "tag:pedestrian"], config={"duration": 1.0})
    assert {r.name for r in env.unwrapped._scenario_refs} == {BRAKES} | pedestrians
    seen = {env.reset(seed=s)[1]["scenario"] for s in range(12)}
    assert BRAKES in seen and seen <= {BRAKES} | pedestrians and seen & pedestrians
    env.close()


def test_tag_and_none_resolve_against_the_bank():
    bank = list_scenarios()
    assert [r.name for r in resolve_scenarios(None)] == bank
    tagged = [n for n in bank if "highway" in scenario_metadata(n).get("tags", [])]
    assert BRAKES in tagged and PEDESTRIAN not in tagged
    assert [r.name for r in resolve_scenarios("tag:highway")] == tagged
    assert all(Path(r.path) == BANK_DIR / r.name / "scenario.scenic" for r in resolve_scenarios(None))


@pytest.fixture(scope="module")
def small_bank(tmp_path_factory):
    """A bank folder holding three of the shipped scenarios and their sidecars."""
    folder = tmp_path_factory.mktemp("bank")
    for name in (BRAKES, PULL_BACK_IN, PEDESTRIAN):
        shutil.copytree(BANK_DIR / name, folder / name)
    return folder


@pytest.mark.slow
def test_tag_selects_tagged_scenarios(small_bank):
    env = gym.make("DV2S-v0", scenario="tag:highway", config={"duration": 1.0}, bank_dir=str(small_bank))
    assert sorted(r.name for r in env.unwrapped._scenario_refs) == [BRAKES, PULL_BACK_IN]
    seen = {env.reset(seed=s)[1]["scenario"] for s in range(10)}
    assert seen == {BRAKES, PULL_BACK_IN}
    env.close()


@pytest.mark.slow
def test_none_samples_the_whole_bank(small_bank):
    env = gym.make("DV2S-v0", scenario=None, config={"duration": 1.0}, bank_dir=str(small_bank))
    seen = {env.reset(seed=s)[1]["scenario"] for s in range(15)}
    assert seen == {BRAKES, PULL_BACK_IN, PEDESTRIAN}
    # The seed fixes the scenario drawn as well as the scene.
    first = env.reset(seed=3)[1]
    env.reset(seed=4)
    again = env.reset(seed=3)[1]
    assert (first["scenario"], first["scene_seed"]) == (again["scenario"], again["scene_seed"])
    env.close()


@pytest.mark.parametrize("name", PAPER_USE_CASES)
def test_paper_scenarios_have_a_sidecar_with_tags(name):
    meta = scenario_metadata(name)
    for key in ("description", "tags", "map", "use_case", "source"):
        assert key in meta, f"{name}.json lacks {key!r}"
    assert "paper_use_case" in meta["tags"]
    assert meta["map"] in (BANK_DIR / name / "scenario.scenic").read_text()


# ------------------------------------------------------------------ determinism

ACTIONS = [IDLE, FASTER, LANE_LEFT, IDLE, SLOWER, 2, IDLE, FASTER, IDLE, IDLE] * 2


def test_same_seed_same_episode_in_process():
    a = rollout(make(PULL_BACK_IN, duration=4.0), 11, ACTIONS)
    b = rollout(make(PULL_BACK_IN, duration=4.0), 11, ACTIONS)
    assert len(a) >= 10
    assert_same_steps(a, b)
    # The same env reset again with the seed replays it as well.
    env = make(PULL_BACK_IN, duration=4.0)
    rollout(env, 99, ACTIONS[:5])
    assert_same_steps(rollout(env, 11, ACTIONS), a)


def test_a_seeded_action_space_stays_seeded_across_resets():
    """highway-env rebuilds its spaces on reset; the env keeps the seeded objects."""

    def samples(env):
        env.action_space.seed(5)
        env.reset(seed=5)
        space = env.action_space
        env.reset(seed=6)
        assert env.action_space is space
        return [int(space.sample()) for _ in range(20)]

    first = make(PULL_BACK_IN)
    used = make(BRAKES)
    used.reset(seed=1)
    used.action_space.sample()  # a space with a history of its own
    assert samples(first) == samples(used)
    first.close()
    used.close()


def test_different_seeds_different_scenes():
    env = make(BRAKES)
    infos, observations = [], []
    for seed in (0, 1, 2):
        obs, info = env.reset(seed=seed)
        infos.append(info)
        observations.append(obs)
    assert len({i["scene_seed"] for i in infos}) == 3
    assert len({i["params"]["ego_speed"] for i in infos}) == 3
    assert not np.array_equal(observations[0], observations[1])
    # Without a seed, successive resets draw new scenes too.
    assert env.reset()[1]["scene_seed"] != env.reset()[1]["scene_seed"]
    env.close()


_DIGEST_SRC = '''
import hashlib, json
import numpy as np
from envs.dv2s_env import DV2SEnv

def episode_digest(scenario, config, seed, actions):
    env = DV2SEnv(scenario=scenario, config=config)
    h = hashlib.sha256()
    obs, info = env.reset(seed=seed)
    h.update(np.ascontiguousarray(obs).tobytes())
    h.update(json.dumps(info, sort_keys=True, default=repr).encode())
    steps = 0
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        h.update(np.ascontiguousarray(obs).tobytes())
        h.update(repr((float(reward), terminated, truncated)).encode())
        h.update(json.dumps(info, sort_keys=True, default=repr).encode())
        if terminated or truncated:
            break
    env.close()
    return f"{steps} {h.hexdigest()}"
'''


@pytest.mark.slow
def test_same_seed_same_episode_across_processes():
    args = (PULL_BACK_IN, {"duration": 4.0}, 11, ACTIONS)
    namespace: dict = {}
    exec(_DIGEST_SRC, namespace)
    here = namespace["episode_digest"](*args)
    code = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r})\n"
        + _DIGEST_SRC
        + f"\nprint(episode_digest(*{args!r}))\n"
    )
    procs = []
    for hash_seed in ("0", "4242"):  # str hashing differs between these interpreters
        env = dict(os.environ, PYTHONHASHSEED=hash_seed)
        procs.append(
            subprocess.Popen(
                [sys.executable, "-c", code], env=env, cwd=str(ROOT),
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            )
        )
    outputs = []
    for proc in procs:
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err[-2000:]
        outputs.append(out.strip().splitlines()[-1])
    assert int(here.split()[0]) >= 10
    assert outputs == [here, here]


# ------------------------------------------------------------------ termination


@pytest.fixture(scope="module")
def collision_episode():
    """The first seed whose ego, always accelerating, rear-ends another car."""
    for seed in range(10):
        env = make(BRAKES, duration=10.0)
        _, info = env.reset(seed=seed)
        ego = env.vehicle
        ahead = {
            v.name
            for v in env.road.vehicles
            if v is not ego and np.dot(v.position - ego.position, ego.direction) > 0
        }
        steps = rollout(env, seed, [FASTER] * 60)
        if steps[-1][2]:
            yield env, seed, steps, ahead
            env.close()
            return
        env.close()
    pytest.fail("no seed below 10 collides when always accelerating")


def test_collision_terminates_and_names_the_other_actor(collision_episode):
    env, _, steps, ahead = collision_episode
    _, reward, terminated, truncated, info = steps[-1]
    assert terminated and not truncated
    assert info["crashed"]
    assert len(info["collisions"]) == 1
    other = info["collisions"][0]
    assert other in ahead  # rear-ended a car that was in front at the start
    vehicles = {v.name: v for v in env.road.vehicles}
    assert vehicles[other].crashed
    # The event is recorded when highway-env first separates the two bodies (its impact), which can be the
    # step before it marks them crashed and the episode ends.
    collision_events = [(i, e) for i, step in enumerate(steps) for e in step[4]["events"] if e["kind"] == "collision"]
    assert collision_events and set(collision_events[0][1]["actors"]) == {"ego", other}
    assert len(steps) - 2 <= collision_events[0][0] <= len(steps) - 1
    assert info["rewards"]["collision"] == 1.0
    first = collision_events[0][0]
    assert all(s[4]["collisions"] == [] for s in steps[:first]) and all(s[4]["collisions"] for s in steps[first:])
    assert not any(s[4]["crashed"] for s in steps[:-1])
    assert reward < min(s[1] for s in steps[1:-1])  # the crash is penalised


def test_collision_does_not_terminate_when_disabled(collision_episode):
    _, seed, steps, _ = collision_episode
    n = len(steps) - 1
    env = make(BRAKES, duration=10.0, terminate_on_collision=False)
    again = rollout(env, seed, [FASTER] * n)
    assert len(again) == n + 1
    assert again[-1][4]["crashed"] and not again[-1][2]
    env.close()


def test_min_ttc_finite_when_closing_in(collision_episode):
    env, _, steps, _ = collision_episode
    ttcs = [s[4]["min_ttc"] for s in steps]
    assert all(a >= b for a, b in zip(ttcs, ttcs[1:]))  # a running minimum
    finite = [t for t in ttcs if math.isfinite(t)]
    assert finite and finite[-1] < env.config["ttc_threshold"]
    assert any(s[4]["rewards"]["low_ttc"] == 1.0 for s in steps[1:])


def test_truncation_at_duration():
    env = make(BRAKES, duration=1.0)
    steps = rollout(env, 4, [SLOWER] * 10)
    assert len(steps) == 1 + 5  # 1 s at 5 decisions per second
    assert [s[3] for s in steps[1:]] == [False] * 4 + [True]
    assert not any(s[2] for s in steps)
    assert env.time == pytest.approx(1.0)
    env.close()


def test_lane_left_emits_lane_change_event():
    env = make(PULL_BACK_IN, duration=3.0)
    steps = rollout(env, 1, [LANE_LEFT] * 15)
    events = [e for s in steps for e in s[4]["events"]]
    ego_changes = [e for e in events if e["kind"] == "lane_change" and e["actors"] == ["ego"]]
    assert ego_changes and all(e["direction"] == "left" for e in ego_changes)
    assert steps[-1][4]["lane_changes"] == len(ego_changes)
    change_steps = [s for s in steps if any(e["actors"] == ["ego"] for e in s[4]["events"])]
    assert all(s[4]["rewards"]["lane_change"] == 1.0 for s in change_steps)
    # Keeping the lane produces no ego lane change.
    idle = rollout(make(PULL_BACK_IN, duration=3.0), 1, [IDLE] * 15)
    assert not any(e["actors"] == ["ego"] for s in idle for e in s[4]["events"] if e["kind"] == "lane_change")
    assert idle[-1][4]["lane_changes"] == 0


ALONE_ON_THE_STREET = """param map = 'urban_two_way'
model scenic.domains.driving.model
egoLane = Uniform(*network.lanes)
ego = new Car at egoLane.centerline.pointAlongBy(Range(60, 460)), with speed 10
"""


def test_driving_off_the_end_of_the_road_terminates():
    """The urban_two_way street is 600 m long; accelerating along it, alone, runs off its end."""
    env = DV2SEnv(scenario=ALONE_ON_THE_STREET, config={"duration": 60.0, "terminate_on_collision": False},
                  trusted=True)
    steps = rollout(env, 0, [FASTER] * 300)
    _, _, terminated, truncated, info = steps[-1]
    assert terminated and not truncated
    assert info["off_road"]
    assert [e["kind"] for e in info["events"]].count("off_road") == 1
    assert info["rewards"]["off_road"] == 1.0
    assert not any(s[4]["off_road"] for s in steps[:-1])
    env.close()


def test_steering_off_the_road_terminates():
    for seed in range(10):
        env = make(BRAKES, duration=5.0, action={"type": "ContinuousAction"}, terminate_on_collision=False)
        steps = rollout(env, seed, [np.array([0.0, 1.0], dtype=np.float32)] * 25)
        env.close()
        if steps[-1][4]["off_road"]:
            break
    else:
        pytest.fail("steering hard right never left the road")
    assert steps[-1][2] and len(steps) <= 15
    # With terminate_off_road disabled the episode goes on after leaving the road.
    env = make(BRAKES, duration=5.0, action={"type": "ContinuousAction"},
               terminate_on_collision=False, terminate_off_road=False)
    more = rollout(env, seed, [np.array([0.0, 1.0], dtype=np.float32)] * (len(steps) + 2))
    assert more[len(steps) - 1][4]["off_road"] and not more[len(steps) - 1][2]
    assert len(more) > len(steps)
    env.close()


# ------------------------------------------------------------------ vector envs


def _gym_maker(seedless_config):
    return lambda: gym.make("DV2S-v0", scenario=BRAKES, config=seedless_config)


CONSTANT_BEHAVIOR = textwrap.dedent(
    """
    param map = 'highway_straight'
    model scenic.domains.driving.model
    monitor Watch():
        while True:
            wait
    require monitor Watch()
    ego = new Car with speed 12
    lead = new Car following roadDirection from ego for 25, with behavior FollowLaneBehavior(target_speed=8)
    """
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario",
    [PULL_BACK_IN, CONSTANT_BEHAVIOR],
    ids=["bank_scenario", "behavior_shared_by_all_scenes"],
)
def test_two_envs_interleaved_in_one_process_match_solo_runs(scenario):
    """Two suspended simulations of one compiled scenario do not disturb each other.

    A behaviour with constant arguments is a single Scenic object shared by every
    scene of the scenario, as is the scenario's dynamic state and its monitors.
    """
    actions = [IDLE, FASTER, LANE_LEFT, IDLE, SLOWER, IDLE, FASTER, IDLE] * 2
    solo = {}
    for seed in (1, 2):
        env = make(scenario, duration=3.0)
        solo[seed] = rollout(env, seed, actions)
        env.close()
    envs = {seed: make(scenario, duration=3.0) for seed in (1, 2)}
    runs = {}
    for seed, env in envs.items():  # the second reset happens while the first episode is suspended
        obs, info = env.reset(seed=seed)
        runs[seed] = [(obs, None, False, False, info)]
    for action in actions:
        for seed, env in envs.items():
            if runs[seed][-1][2] or runs[seed][-1][3]:
                continue
            runs[seed].append(env.step(action))
    for seed in (1, 2):
        assert len(runs[seed]) > 5
        assert_same_steps(runs[seed], solo[seed])
    assert not np.array_equal(runs[1][0][0], runs[2][0][0])
    for env in envs.values():
        env.close()


def test_sync_vector_env_matches_single_envs():
    config = {"duration": 4.0}
    venv = gym.vector.SyncVectorEnv([_gym_maker(config), _gym_maker(config)])
    obs, infos = venv.reset(seed=[21, 22])
    assert obs.shape == (2, 8, 7)
    assert list(infos["scenario"]) == [BRAKES, BRAKES]
    trajectories = [[obs[0]], [obs[1]]]
    for _ in range(10):
        obs, rewards, terminated, truncated, infos = venv.step(np.array([IDLE, FASTER]))
        assert rewards.shape == (2,)
        for i in range(2):
            trajectories[i].append(obs[i])
        if terminated.any() or truncated.any():
            break
    venv.close()
    for i, (seed, action) in enumerate(((21, IDLE), (22, FASTER))):
        solo = rollout(make(BRAKES, duration=4.0), seed, [action] * (len(trajectories[i]) - 1))
        assert all(np.array_equal(a, s[0]) for a, s in zip(trajectories[i], solo))


def _check_vector_autoreset(step, obs_shape, n_steps=10):
    """Episodes of 1 s (5 steps) are truncated and restarted by the vector env."""
    dones = []
    for _ in range(n_steps):
        obs, rewards, done = step()
        assert obs.shape == obs_shape and np.isfinite(rewards).all()
        dones.append(done)
    return dones


def test_async_vector_env_steps_and_autoresets():
    config = {"duration": 1.0}
    venv = gym.vector.AsyncVectorEnv([_gym_maker(config), _gym_maker(config)], context="fork")
    try:
        obs, infos = venv.reset(seed=[1, 2])
        assert obs.shape == (2, 8, 7)
        assert infos["scene_seed"][0] != infos["scene_seed"][1]

        def step():
            obs, rewards, terminated, truncated, _ = venv.step(np.array([IDLE, SLOWER]))
            return obs, rewards, (terminated | truncated).tolist()

        dones = _check_vector_autoreset(step, (2, 8, 7))
    finally:
        venv.close()
    assert dones[4] == [True, True]  # truncated after 1 s
    assert dones[5] == [False, False]  # the autoreset step
    assert not any(any(d) for d in dones[:4])


def test_sb3_dummy_vec_env():
    from stable_baselines3.common.vec_env import DummyVecEnv

    fn = functools.partial(DV2SEnv, scenario=BRAKES, config={"duration": 1.0})
    venv = DummyVecEnv([fn, fn])
    venv.seed(3)  # env i is reset with seed 3 + i
    obs = venv.reset()
    assert obs.shape == (2, 8, 7)
    assert np.array_equal(obs[0], make(BRAKES).reset(seed=3)[0])
    assert np.array_equal(obs[1], make(BRAKES).reset(seed=4)[0])
    done_at = []
    for i in range(10):
        obs, rewards, dones, infos = venv.step(np.array([IDLE, FASTER]))
        assert obs.shape == (2, 8, 7) and rewards.shape == (2,)
        if dones.any():
            done_at.append(i)
            assert all("terminal_observation" in infos[j] for j in np.nonzero(dones)[0])
    venv.close()
    assert 4 in done_at


@pytest.mark.parametrize(
    "start_method",
    ["fork", pytest.param("forkserver", marks=pytest.mark.slow)],
)
def test_sb3_subproc_vec_env(start_method):
    """``forkserver`` (SB3's default) pickles the env factory to fresh processes, which
    compile the scenario again; ``fork`` inherits this process's compiled scenarios."""
    from stable_baselines3.common.vec_env import SubprocVecEnv

    fn = functools.partial(DV2SEnv, scenario=BRAKES, config={"duration": 1.0})
    venv = SubprocVecEnv([fn, fn], start_method=start_method)
    try:
        venv.seed(3)
        obs = venv.reset()
        assert obs.shape == (2, 8, 7)
        # The worker processes sample the same scenes as this process.
        assert np.array_equal(obs[0], make(BRAKES).reset(seed=3)[0])
        assert np.array_equal(obs[1], make(BRAKES).reset(seed=4)[0])
        done_at = []
        for i in range(10):
            obs, rewards, dones, infos = venv.step(np.array([IDLE, FASTER]))
            assert obs.shape == (2, 8, 7) and rewards.shape == (2,)
            if dones.any():
                done_at.append(i)
        assert 4 in done_at
    finally:
        venv.close()


# -------------------------------------------------------------------- rendering


def test_rgb_array_frame_shows_the_ego():
    env = make(BRAKES, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8
    assert frame.shape == (env.config["screen_height"], env.config["screen_width"], 3)
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 4  # road, markings, cars
    assert pixels_of(frame, EGO_COLOR) > 50
    assert pixels_of(frame, PEDESTRIAN_COLOR) == 0  # no pedestrian in this scenario
    env.step(FASTER)
    assert not np.array_equal(env.render(), frame)
    env.close()


def test_pedestrian_is_drawn_once_in_view():
    env = make(PEDESTRIAN, render_mode="rgb_array", duration=4.0)
    env.reset(seed=0)
    pedestrian = next(v for v in env.road.vehicles if type(v).__name__ == "Pedestrian")
    half_view = env.config["screen_width"] / 2 / env.config["scaling"]
    for _ in range(20):
        if np.linalg.norm(pedestrian.position - env.vehicle.position) < 0.8 * half_view:
            break
        env.step(IDLE)
    else:
        pytest.fail("the pedestrian never came into view")
    frame = env.render()
    assert pixels_of(frame, PEDESTRIAN_COLOR) >= 5
    assert pixels_of(frame, EGO_COLOR) > 50
    env.close()


def test_record_episode_writes_a_readable_webm(tmp_path):
    from dv2s_gym.pipeline.video import read_video

    from envs.recording import record_episode

    env = make(BRAKES, render_mode="rgb_array", duration=1.0)
    path = tmp_path / "episode.webm"
    summary = record_episode(env, path, policy=lambda obs, info: IDLE, seed=1)
    env.close()
    assert path.is_file() and path.stat().st_size > 0
    assert summary["steps"] == 5 and summary["frames"] == summary["steps"] + 1
    frames = read_video(path, fps=None, max_frames=10**6, max_pixels=10**9).frames  # every frame, full size
    assert len(frames) == summary["frames"]
    assert frames[0].shape == (env.config["screen_height"], env.config["screen_width"], 3)
    assert frames[0].std() > 0
    assert not list(tmp_path.glob(".*tmp*"))  # the temporary file was moved into place


def test_record_episode_needs_rgb_array(tmp_path):
    from envs.recording import record_episode

    with pytest.raises(ValueError, match="rgb_array"):
        record_episode(make(BRAKES), tmp_path / "x.webm")


# ------------------------------------------------------------ reset and memory


def _rss_bytes() -> int:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="needs /proc")
def test_many_resets_work_without_memory_growth():
    env = make(BRAKES)
    for seed in range(10):  # warm up caches
        env.reset(seed=seed)
        env.step(IDLE)
    before = _rss_bytes()
    scene_seeds = set()
    for seed in range(100):
        obs, info = env.reset(seed=1000 + seed)
        assert env.observation_space.contains(obs) and info["scenario"] == BRAKES
        scene_seeds.add(info["scene_seed"])
        if seed % 10 == 0:
            env.step(IDLE)
    growth = _rss_bytes() - before
    env.close()
    assert len(scene_seeds) == 100
    assert growth < 100 * 2**20, f"RSS grew by {growth / 2**20:.1f} MB over 100 resets"


def test_importing_the_env_leaves_the_users_tracebacks_alone():
    """Scenic installs its own sys.excepthook on import; the env puts Python's back."""
    code = ("import sys\nimport envs.dv2s_env\nimport scenic.core.errors\n"
            "print(sys.excepthook is sys.__excepthook__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=str(ROOT))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"
