"""The route features of the Kinematics observation (``route_turn``, ``route_bearing``): what they say on junction
scenarios, that only the ego's row carries them, that the default observation does not change, and that a policy
trained with them runs, mines, fine-tunes and is regression-tested only with them (a mismatch is an error)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from envs.dv2s_env import DV2SEnv
from envs.errors import UnknownConfigKeyError
from envs.observations import KINEMATIC_FEATURES, ROUTE_FEATURES
from policies import PolicySpaceError, load_policy
from scenario_bank.records import HeldOutEpisode

DEFAULT_FEATURES = ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"]
ROUTE_OBSERVATION = {"type": "Kinematics", "vehicles_count": 8, "features": DEFAULT_FEATURES + list(ROUTE_FEATURES),
                     "absolute": False, "normalize": True, "see_behind": True}
ROUTE_CONFIG = {"observation": ROUTE_OBSERVATION}
TURN, BEARING = len(DEFAULT_FEATURES), len(DEFAULT_FEATURES) + 1


def _first_observations(scenario: str, seed: int = 0, steps: int = 1, config=None):
    env = DV2SEnv(scenario=scenario, config=dict(config or ROUTE_CONFIG))
    try:
        obs, _ = env.reset(seed=seed)
        seen = [obs]
        for _ in range(steps - 1):
            obs, _, terminated, truncated, _ = env.step(1)  # IDLE
            seen.append(obs)
            if terminated or truncated:
                break
        return seen, env
    finally:
        env.close()


def test_the_default_observation_is_unchanged():
    observation = DV2SEnv.default_config()["observation"]
    assert observation["features"] == DEFAULT_FEATURES
    assert not set(ROUTE_FEATURES) & set(observation["features"])


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_a_left_turn_differs_from_straight_on_and_from_a_right_turn(seed):
    """On the T-junction the ego turns left (its route: approach, connecting lane, side road): +0.5 is 90 degrees
    to the left; an ego going straight over its crossroads has 0; one turning right has about -0.5."""
    left, _ = _first_observations("urban_t_junction_left_turn_oncoming", seed)
    straight, _ = _first_observations("urban_straight_crossing_paths", seed)
    right, _ = _first_observations("urban_obstacle_after_right_turn", seed)
    assert left[0][0, TURN] == pytest.approx(0.5, abs=0.1) and left[0][0, BEARING] > 0.2
    assert straight[0][0, TURN] == pytest.approx(0.0, abs=0.05) and abs(straight[0][0, BEARING]) < 0.05
    assert right[0][0, TURN] == pytest.approx(-0.5, abs=0.1) and right[0][0, BEARING] < -0.2


@pytest.mark.slow
def test_the_turn_feature_falls_to_zero_once_the_ego_has_turned_and_others_rows_stay_zero():
    seen, _ = _first_observations("urban_obstacle_after_right_turn", 0, steps=40)
    turns = [float(obs[0, TURN]) for obs in seen]
    assert turns[0] < -0.4 and abs(turns[-1]) < 0.1  # the ego (IDLE follows its route) has made its right turn
    others = np.concatenate([obs[1:, TURN:] for obs in seen])
    present = np.concatenate([obs[1:, 0] for obs in seen])
    assert present.sum() > 0 and not others.any()  # other vehicles are observed, never their routes


@pytest.mark.slow
def test_no_route_is_zero_and_observe_intentions_does_not_leak_routes():
    """Without ``with route`` in the script (a highway scenario) the ego's features are 0; with highway-env's
    ``observe_intentions`` the other vehicles' own ``cos_d``/``sin_d`` show, but never a route feature."""
    seen, _ = _first_observations("highway_cut_in_from_left", 0, steps=5)
    assert all(not obs[:, TURN:].any() for obs in seen)
    config = {"observation": {**ROUTE_OBSERVATION, "observe_intentions": True}}
    seen, _ = _first_observations("urban_t_junction_left_turn_oncoming", 0, steps=5, config=config)
    assert all(obs[0, TURN] > 0.3 and not obs[1:, TURN:].any() for obs in seen)


def test_unknown_or_repeated_features_are_refused_in_one_line():
    from envs.dv2s_env import check_env_config

    with pytest.raises(UnknownConfigKeyError, match="unknown Kinematics feature 'route_trun'.*did you mean 'route_turn'"):
        check_env_config({"observation": {**ROUTE_OBSERVATION, "features": ["presence", "route_trun"]}})
    with pytest.raises(UnknownConfigKeyError, match="'x' more than once"):
        check_env_config({"observation": {**ROUTE_OBSERVATION, "features": ["presence", "x", "x"]}})
    with pytest.raises(UnknownConfigKeyError, match="non-empty list"):
        check_env_config({"observation": {**ROUTE_OBSERVATION, "features": "presence"}})
    check_env_config(ROUTE_CONFIG)
    assert set(ROUTE_FEATURES) < set(KINEMATIC_FEATURES)


# --------------------------------------------------------------------------- policies carry their observation
def _ppo_with_card(folder: Path, shape, env_config) -> Path:
    """A PPO checkpoint for observations of ``shape`` with a card naming ``env_config`` (as `dv2s train` writes)."""
    from stable_baselines3 import PPO

    class Dummy(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, shape, np.float32)
        action_space = gym.spaces.Discrete(5)

        def reset(self, *, seed=None, options=None):
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, True, False, {}

    folder.mkdir(parents=True, exist_ok=True)
    PPO("MlpPolicy", Dummy(), n_steps=8, batch_size=8, seed=0, device="cpu").save(folder / "model.zip")
    (folder / "model_card.json").write_text(json.dumps({"algorithm": "ppo", "env_config": env_config}))
    return folder / "model.zip"


@pytest.fixture(scope="module")
def route_env():
    env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_cut_in_from_left", config=ROUTE_CONFIG)
    yield env
    env.close()


@pytest.fixture(scope="module")
def default_env():
    env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_cut_in_from_left")
    yield env
    env.close()


@pytest.mark.slow
def test_a_route_policy_binds_only_to_envs_that_observe_its_routes(tmp_path, route_env, default_env):
    checkpoint = _ppo_with_card(tmp_path / "route", (8, 9), ROUTE_CONFIG)
    policy = load_policy(f"ppo:{checkpoint}")
    policy.bind([route_env])
    obs, _ = route_env.reset(seed=0)
    assert policy.act(obs[None]).shape == (1,)
    with pytest.raises(PolicySpaceError, match=r"\(8, 9\).*env has .*\(8, 7\)"):
        load_policy(f"ppo:{checkpoint}").bind([default_env])
    # the same shape with other features: the card's config decides, never a silent default
    swapped = dict(ROUTE_OBSERVATION, features=["presence", "x", "y", "vx", "vy", "route_turn", "route_bearing"])
    same_shape = _ppo_with_card(tmp_path / "swapped", (8, 7), {"observation": swapped})
    with pytest.raises(PolicySpaceError, match=r"trained with another observation.*features: trained \[.*'route_turn'"):
        load_policy(f"ppo:{same_shape}").bind([default_env])
    with pytest.raises(PolicySpaceError, match="another observation"):  # a noisy copy is checked the same way
        load_policy(f"ppo:{same_shape}?action_noise=0.1").check_env_config({})


def test_an_option_left_at_its_default_is_the_same_observation(tmp_path):
    """A card or env config that spells out highway-env's own default of an option observes alike."""
    checkpoint = _ppo_with_card(tmp_path / "route", (8, 9), ROUTE_CONFIG)
    policy = load_policy(f"ppo:{checkpoint}")
    policy.check_env_config({"observation": {**ROUTE_OBSERVATION, "clip": True, "order": "sorted"}})
    with pytest.raises(PolicySpaceError, match="see_behind: trained True, env False"):
        policy.check_env_config({"observation": {**ROUTE_OBSERVATION, "see_behind": False}})
    # a card without an observation section was trained with the default one
    default = load_policy(f"ppo:{_ppo_with_card(tmp_path / 'default', (8, 7), {'reward_weights': {}})}")
    default.check_env_config({})
    default.check_env_config({"observation": DV2SEnv.default_config()["observation"]})
    with pytest.raises(PolicySpaceError, match="route_turn"):
        default.check_env_config(ROUTE_CONFIG)


@pytest.mark.slow
def test_fine_tuning_with_another_observation_is_refused_before_any_work(tmp_path):
    from fine_tune_helpers import dagger_fine_tune, fine_tune
    from policies.training import TrainingError

    checkpoint = _ppo_with_card(tmp_path / "route", (8, 9), ROUTE_CONFIG)
    for tune in (dagger_fine_tune, fine_tune):
        out = tmp_path / f"out_{tune.__name__}"
        with pytest.raises(TrainingError, match="cannot fine-tune here: .*another observation"):
            tune(f"ppo:{checkpoint}", out=out, steps=10, weights={"highway_cut_in_from_left": 1.0}, n_envs=1,
                 vec_env="dummy", progress_bar=False, env_config={}, log=lambda _: None)
        assert not (out / "model.zip").exists()


@pytest.mark.slow
def test_mining_and_regression_refuse_a_config_the_policy_was_not_trained_with(tmp_path):
    from dv2s_gym.mining.miner import MineSettings, _check_can_mine
    from dv2s_gym.regress.errors import RegressError
    from dv2s_gym.regress.runner import _policy_info

    checkpoint = _ppo_with_card(tmp_path / "route", (8, 9), ROUTE_CONFIG)
    spec = f"ppo:{checkpoint}"
    with pytest.raises(PolicySpaceError, match="another observation"):
        _check_can_mine(spec, MineSettings(budget=1, env_config={}))
    _check_can_mine(spec, MineSettings(budget=1, env_config=ROUTE_CONFIG))
    with pytest.raises(RegressError, match="--config: .*another observation"):
        _policy_info(spec, {})
    assert _policy_info(spec, ROUTE_CONFIG).card.env_config == ROUTE_CONFIG


def test_the_loop_runs_every_step_with_the_route_policys_observation(tmp_path, monkeypatch):
    """Mining, the held-out episodes, both fine-tuning arms, the untouched set and the regression test of `dv2s loop`
    all get the starting policy's card's config, route observation included."""
    import dv2s_gym.loop.heldout as heldout
    import dv2s_gym.regress.runner as runner
    import policies.imitation as imitation
    from loop_helpers import FakeMiner, run_loop

    sources = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
    config = {**ROUTE_CONFIG, "reward_weights": {"collision": -2.0}}
    checkpoint = _ppo_with_card(tmp_path / "start", (8, 9), config)
    fine_tunes, evaluations, regressions = [], [], []

    def fake_dagger(spec, train_config, dagger=None, *, log=print):
        fine_tunes.append(train_config.env_config)
        out = Path(train_config.out)
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(checkpoint, out / "model.zip")
        (out / "model_card.json").write_text(json.dumps({"algorithm": "ppo", "env_config": train_config.env_config,
                                                         "fine_tune": {"method": "dagger"}}))
        return out / "model.zip"

    def fake_evaluate(role, policy, episodes, *, env_config=None, **kwargs):
        evaluations.append(env_config)
        return [HeldOutEpisode(role=role, scenario=s, seed=seed, failed=role == "before")
                for s, seed in episodes]

    def fake_regression(candidate, baseline, settings, **kwargs):
        regressions.append(settings.env_config)
        return {"verdict": "PASS", "overall": {}}

    monkeypatch.setattr(imitation, "dagger_fine_tune", fake_dagger)
    monkeypatch.setattr(heldout, "evaluate_heldout", fake_evaluate)
    monkeypatch.setattr(runner, "run_regression", fake_regression)
    miner = FakeMiner(sources, failures_per_round=4)
    run_loop(f"ppo:{checkpoint}", out=tmp_path / "loop", miner=miner, budget=6, fine_tune_steps=100, k_eval=3,
             regress_episodes=1, workers=1, n_envs=1, progress=False, scenarios=sources, min_heldout_episodes=1,
             min_heldout_families=1, untouched_seeds=1, log=lambda _: None)
    assert miner.calls[0]["env_config"] == config
    assert len(fine_tunes) == 2 and all(c == config for c in fine_tunes)  # DAgger: the policy's config, whole
    assert evaluations and all(c == config for c in evaluations)
    assert regressions == [config] * 3  # the untouched set (against start, then the control) and the bank
