"""The policy registry: names, checkpoints, module:attribute specs, options and the errors users see."""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
import pytest

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from policies import Policy, PolicyError, PolicySpaceError, load_policy, register_policy, registered_policies
from policies.registry import ActionNoise, CallablePolicy, parse_spec

SCENARIO = "highway_cut_in_from_left"


@pytest.fixture(scope="module")
def envs():
    made = [gym.make("dv2s_gym:DV2S-v0", scenario=SCENARIO) for _ in range(2)]
    yield made
    for env in made:
        env.close()


def test_builtin_names_are_registered():
    assert {"rule", "idm", "keep_lane", "random", "dv2s-ppo"} <= set(registered_policies())


def test_spec_options_are_typed():
    assert parse_spec("idm?time_headway=2.5&threshold=1&desired_speed=none") == (
        "idm", {"time_headway": 2.5, "threshold": 1, "desired_speed": None})
    with pytest.raises(PolicyError, match="not key=value"):
        parse_spec("idm?oops")


def test_unknown_name_lists_what_exists():
    with pytest.raises(PolicyError, match="unknown policy 'nope'.*keep_lane.*rule"):
        load_policy("nope")


def test_state_drivers_act_batched_on_their_own_envs(envs):
    policy = load_policy("rule")
    with pytest.raises(PolicyError, match="bind"):
        policy.act(np.zeros((1, 8, 7)))
    policy.bind(envs)
    observations = np.stack([env.reset(seed=seed)[0] for seed, env in enumerate(envs)])
    actions = policy.act(observations)
    assert actions.shape == (2,) and all(0 <= a < 5 for a in actions)
    # each row is the driver of its own env: the same as a driver bound to that env alone
    single = load_policy("rule")
    single.bind([envs[1]])
    assert single.act(observations[1:])[0] == actions[1]


def test_action_noise_replaces_actions_at_its_rate(envs):
    constant = CallablePolicy("always_idle", lambda obs: 1)
    noisy = load_policy(constant, action_noise=0.4)
    assert isinstance(noisy, ActionNoise)
    noisy.bind(envs[:1])
    actions = np.concatenate([noisy.act(np.zeros((1, 8, 7))) for _ in range(2000)])
    changed = np.mean(actions != 1)
    # a replacement draws one of 5 actions uniformly, so 4/5 of them differ from IDLE
    assert abs(changed - 0.4 * 0.8) < 0.04
    with pytest.raises(PolicyError, match="probability"):
        load_policy("keep_lane?action_noise=1.5")


def test_registered_callables_and_module_attribute_specs(envs):
    register_policy("test_brake_always", lambda: (lambda obs: 4), overwrite=True)
    policy = load_policy("test_brake_always")
    assert isinstance(policy, Policy) and policy.act(np.zeros((3, 8, 7))).tolist() == [4, 4, 4]
    with pytest.raises(PolicyError, match="already registered"):
        register_policy("test_brake_always", lambda: None)
    via_import = load_policy("policies.registry:RandomPolicy?seed=3")
    via_import.bind(envs[:1])
    assert via_import.act(np.zeros((4, 8, 7))).shape == (4,)
    with pytest.raises(PolicyError, match="module 'policies.registry' has no 'NoSuchThing'; it defines: "):
        load_policy("policies.registry:NoSuchThing")


def _tiny_ppo(path, observation_space):
    from stable_baselines3 import PPO

    class Dummy(gym.Env):
        def __init__(self):
            self.observation_space = observation_space
            self.action_space = gym.spaces.Discrete(5)

        def reset(self, *, seed=None, options=None):
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, True, False, {}

    model = PPO("MlpPolicy", Dummy(), n_steps=8, batch_size=8, seed=0, device="cpu")
    model.save(path)
    return path


def test_sb3_checkpoint_loads_and_acts(envs, tmp_path):
    checkpoint = _tiny_ppo(tmp_path / "model.zip", envs[0].observation_space)
    policy = load_policy(str(checkpoint))
    assert policy.card.algorithm == "ppo"
    policy.bind(envs)
    observations = np.stack([env.reset(seed=0)[0] for env in envs])
    assert policy.act(observations).shape == (2,)
    assert load_policy(f"ppo:{checkpoint}").act(observations).tolist() == policy.act(observations).tolist()


def test_checkpoint_with_another_observation_space_says_which(envs, tmp_path):
    checkpoint = _tiny_ppo(tmp_path / "model.zip", gym.spaces.Box(-1, 1, (5, 5), np.float32))
    policy = load_policy(str(checkpoint))
    with pytest.raises(PolicySpaceError, match=r"observation space Box.*\(5, 5\).*env has Box.*\(8, 7\)"):
        policy.bind(envs[:1])


def test_broken_and_missing_checkpoints_are_clear_errors(tmp_path):
    with pytest.raises(PolicyError, match="does not exist"):
        load_policy(str(tmp_path / "missing.zip"))
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"not a zip at all")
    with pytest.raises(PolicyError, match="does not load as an SB3 model"):
        load_policy(str(broken))


@pytest.fixture
def policy_modules(monkeypatch, tmp_path):
    """Three modules beside the test: one defining some names, one whose code raises, one missing a dependency."""
    (tmp_path / "polmod_a.py").write_text("X = 1\n\ndef make():\n    return 3\n\nclass Driver:\n    pass\n")
    (tmp_path / "polmod_boom.py").write_text('raise RuntimeError("boom")\n')
    (tmp_path / "polmod_dep.py").write_text("import no_such_dependency_module\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    for name in ("polmod_a", "polmod_boom", "polmod_dep"):
        sys.modules.pop(name, None)


def test_a_spec_that_cannot_load_says_which_of_three_cases(policy_modules):
    with pytest.raises(PolicyError, match="module 'polmod_a' has no 'nosuch'; it defines: Driver, X, make$"):
        load_policy("polmod_a:nosuch")
    with pytest.raises(PolicyError) as raised:
        load_policy("polmod_boom:x")
    assert "importing it raised RuntimeError: boom; run `python -c 'import polmod_boom'`" in str(raised.value)
    assert "PYTHONPATH" not in str(raised.value)
    with pytest.raises(PolicyError) as raised:
        load_policy("polmod_dep:x")
    assert "No module named 'no_such_dependency_module'" in str(raised.value)
    assert "PYTHONPATH" not in str(raised.value)
    with pytest.raises(PolicyError, match="cannot import module 'polmod_none'.*PYTHONPATH"):
        load_policy("polmod_none:x")


def test_a_spec_naming_a_value_says_an_int(policy_modules):
    with pytest.raises(PolicyError, match="'polmod_a:X' is an int, not a Policy"):
        load_policy("polmod_a:X")
    with pytest.raises(PolicyError, match="returned an int, not a Policy"):
        load_policy("polmod_a:make")
