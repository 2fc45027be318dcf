"""``DV2S-v0`` config checks: a misspelt key or value anywhere in ``config=`` (reward terms, observation and
action options, ``ego_policy``) is refused with one line naming it, the choices and a suggestion; every valid
key keeps working."""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

import gymnasium as gym
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import dv2s_gym  # noqa: E402,F401  (registers DV2S-v0)
from envs.config_check import REQUIRED_OBSERVATION_KEYS, check_config, type_options  # noqa: E402
from envs.dv2s_env import DV2SEnv  # noqa: E402
from envs.errors import ACTION_TYPES, OBSERVATION_TYPES, UnknownConfigKeyError  # noqa: E402

BRAKES = "highway_lead_vehicle_brakes"
DEFAULTS = DV2SEnv.default_config()

MISTAKES = [
    ({"reward_weights": {"colision": -5}},
     r"^unknown reward term 'colision' \(did you mean 'collision'\?\) in config\['reward_weights'\]; the terms are "
     r"collision, high_speed, lane_change, low_ttc, off_road, standing$"),
    ({"observation": {"type": "Kinematics", "vehicle_count": 3}},
     r"^config\['observation'\] has 'vehicle_count' \(did you mean 'vehicles_count'\?\), which highway-env's "
     r"Kinematics observation does not take \(it would be ignored\); its keys are .*\bvehicles_count\b"),
    ({"action": {"type": "DiscreteMetaAction", "target_speed": [10, 20]}},
     r"^config\['action'\] has 'target_speed' \(did you mean 'target_speeds'\?\), which highway-env's "
     r"DiscreteMetaAction action does not take .*; its keys are lateral, longitudinal, target_speeds, type$"),
    ({"ego_policy": "scenicc"}, r"^unknown ego_policy 'scenicc' \(did you mean 'scenic'\?\); it is 'agent' or "
                                r"'scenic'$"),
    ({"reward_weights": {"collision": "high"}},
     r"^config\['reward_weights'\]\['collision'\] must be a finite number, not 'high'$"),
    ({"reward_weights": {"collision": float("nan")}}, r"must be a finite number, not nan"),
    ({"reward_weights": -1.0}, r"^config\['reward_weights'\] must be a dict of reward term to weight"),
    # DiscreteAction does not pass its keywords on to ContinuousAction: speed_range would be dropped
    ({"action": {"type": "DiscreteAction", "speed_range": [0, 30]}},
     r"^config\['action'\] has 'speed_range'.* DiscreteAction action does not take"),
]


@pytest.mark.parametrize("config, message", MISTAKES, ids=lambda v: str(v)[:40] if isinstance(v, dict) else None)
def test_a_nested_mistake_is_one_line_naming_it_and_the_choices(config, message):
    with pytest.raises(UnknownConfigKeyError, match=message) as caught:
        check_config(config, DEFAULTS)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("config, message", MISTAKES[:4], ids=["reward", "observation", "action", "ego_policy"])
def test_the_env_refuses_a_nested_mistake_before_building(config, message):
    with pytest.raises(UnknownConfigKeyError, match=message):
        gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES, config=config)


def test_a_jailed_env_refuses_a_nested_mistake_before_starting_its_worker():
    text = (ROOT / "scenario_bank" / "scenarios" / BRAKES / "scenario.scenic").read_text() + "\n# edited\n"
    with pytest.raises(UnknownConfigKeyError, match=r"'colision' \(did you mean 'collision'\?\)"):
        DV2SEnv(scenario=text, config={"reward_weights": {"colision": -5}})


# The options highway-env documents for each type DV2S-v0 supports, written out here rather than read from
# highway-env, so that the check reading them from the classes is tested against an independent list.
DOCUMENTED = {
    ("observation", "Kinematics"): ["vehicles_count", "features", "features_range", "absolute", "order",
                                    "normalize", "clip", "see_behind", "observe_intentions", "include_obstacles"],
    ("observation", "OccupancyGrid"): ["features", "grid_size", "grid_step", "features_range", "absolute",
                                       "align_to_vehicle_axes", "clip", "as_image"],
    ("observation", "TimeToCollision"): ["horizon"],
    ("observation", "LidarObservation"): ["cells", "maximum_range", "normalize"],
    ("observation", "GrayscaleObservation"): ["observation_shape", "stack_size", "weights", "scaling",
                                              "centering_position"],
    ("action", "DiscreteMetaAction"): ["longitudinal", "lateral", "target_speeds"],
    ("action", "ContinuousAction"): ["acceleration_range", "steering_range", "speed_range", "longitudinal",
                                     "lateral", "dynamical", "clip"],
    ("action", "DiscreteAction"): ["acceleration_range", "steering_range", "longitudinal", "lateral", "dynamical",
                                   "clip", "actions_per_axis"],
}


def test_every_supported_type_is_listed_here():
    assert {t for s, t in DOCUMENTED if s == "observation"} == set(OBSERVATION_TYPES)
    assert {t for s, t in DOCUMENTED if s == "action"} == set(ACTION_TYPES)


@pytest.mark.parametrize("section, kind", sorted(DOCUMENTED))
def test_every_documented_option_of_a_type_is_accepted(section, kind):
    assert type_options(section, kind) == {"type", *DOCUMENTED[section, kind]}
    config = {section: {"type": kind, **{key: None for key in DOCUMENTED[section, kind]}}}
    check_config(config, DEFAULTS)


VALUE_MISTAKES = [
    ({"duration": "ten"}, r"^config\['duration'\] is 'ten'; it must be a number of seconds > 0, e\.g\. 20\.0 "
                          r"\(the default\)$"),
    ({"duration": -5}, r"^config\['duration'\] is -5; it must be a number of seconds > 0"),
    ({"duration": float("nan")}, r"^config\['duration'\] is nan; it must be a number"),
    ({"duration": True}, r"^config\['duration'\] is True; it must be a number"),
    ({"simulation_frequency": 0}, r"^config\['simulation_frequency'\] is 0; it must be a number of Hz > 0"),
    ({"policy_frequency": "5"}, r"^config\['policy_frequency'\] is '5'; it must be a number of Hz > 0"),
    ({"policy_frequency": 30}, r"^config\['policy_frequency'\] is 30, above the simulation_frequency 15; .*: "
                               r"lower policy_frequency or raise simulation_frequency$"),
    ({"max_sample_iterations": 2.5}, r"^config\['max_sample_iterations'\] is 2\.5; it must be a whole number > 0"),
    ({"step_time_limit": -1}, r"^config\['step_time_limit'\] is -1; it must be a number of seconds \(or None"),
    ({"ttc_threshold": -0.5}, r"^config\['ttc_threshold'\] is -0\.5; it must be a number of seconds >= 0"),
    ({"screen_width": "600"}, r"^config\['screen_width'\] is '600'; it must be a whole number of pixels > 0"),
    ({"reward_speed_range": [30, 10]}, r"^config\['reward_speed_range'\] is \[30, 10\]; it must be \[low, high\]"),
    ({"observation": {"type": "Kinematics", "vehicles_count": "ten"}},
     r"^config\['observation'\]\['vehicles_count'\] is 'ten'; it must be a whole number > 0$"),
    ({"observation": {"type": "Kinematics", "vehicles_count": -2}},
     r"^config\['observation'\]\['vehicles_count'\] is -2; it must be a whole number > 0$"),
]


@pytest.mark.parametrize("config, message", VALUE_MISTAKES, ids=lambda v: str(v)[:40] if isinstance(v, dict) else None)
def test_a_numeric_value_of_the_wrong_type_or_range_is_one_line_naming_key_value_and_expectation(config, message):
    with pytest.raises(UnknownConfigKeyError, match=message) as caught:
        check_config(config, DEFAULTS)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("config, message", VALUE_MISTAKES[:2], ids=["type", "sign"])
def test_the_env_refuses_a_wrong_numeric_value_at_make_not_at_the_first_step(config, message):
    with pytest.raises(UnknownConfigKeyError, match=message):
        gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES, config=config)


def test_configure_checks_the_values_it_sets():
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0})
    with pytest.raises(UnknownConfigKeyError, match=r"^config\['duration'\] is 'ten'"):
        env.configure({"duration": "ten"})
    with pytest.raises(UnknownConfigKeyError, match=r"above the simulation_frequency 15"):
        env.configure({"policy_frequency": 20})
    env.configure({"duration": 2, "step_time_limit": None})
    assert env.config["duration"] == 2 and env.config["step_time_limit"] is None
    env.close()


def test_the_default_config_and_every_reward_term_pass():
    check_config(DEFAULTS, DEFAULTS)
    check_config({"reward_weights": {term: 0.5 for term in DEFAULTS["reward_weights"]}, "ego_policy": "scenic"},
                 DEFAULTS)


def _defaults_of(section: str, kind: str) -> dict:
    """Every option of the type at its default value (the required ones at an example value)."""
    from envs.config_check import _CLASS_NAMES

    module = __import__(f"highway_env.envs.common.{section}", fromlist=["x"])
    values = {}
    for klass in getattr(module, _CLASS_NAMES[section][kind]).__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        for parameter in inspect.signature(init).parameters.values():
            if parameter.default is not inspect.Parameter.empty:
                values.setdefault(parameter.name, parameter.default)
    values = {key: value for key, value in values.items() if key in DOCUMENTED[section, kind]}
    return {"type": kind, **values, **REQUIRED_OBSERVATION_KEYS.get(kind, {})}


@pytest.mark.parametrize("section, kind", sorted(DOCUMENTED))
def test_an_env_with_every_option_of_a_type_at_its_default_runs(section, kind):
    config = {"duration": 1.0, section: _defaults_of(section, kind)}
    env = DV2SEnv(scenario=BRAKES, config=config)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    env.step(env.action_space.sample())
    env.close()


def test_a_valid_nested_key_takes_effect():
    env = gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES,
                   config={"duration": 1.0, "observation": {"type": "Kinematics", "vehicles_count": 3}})
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 5)  # highway-env's five default features, three vehicles
    env.close()


@pytest.mark.parametrize("command", [
    ["regress", "--policy", "rule", "--scenarios", BRAKES, "--episodes", "1"],
    ["mine", "--policy", "rule", "--budget", "2", "--scenarios", BRAKES, "--no-convert"],
    ["train", "--steps", "100"],
], ids=lambda c: c[0])
@pytest.mark.parametrize("config, message", MISTAKES[:4], ids=["reward", "observation", "action", "ego_policy"])
def test_a_commands_config_gets_the_same_check_before_any_episode(command, config, message, tmp_path, capsys):
    import json

    from dv2s_gym.cli import main

    out = tmp_path / "out"
    code = main([*command, "--out", str(out), "--config", json.dumps(config)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.count("\n") == 0, err
    assert re.search(message.lstrip("^"), err), err
    assert not out.exists() or not any(out.iterdir())  # refused before a run folder was filled


@pytest.mark.parametrize("scenario", [BRAKES, "edited"])
def test_an_unknown_render_mode_is_named_with_the_choices(scenario):
    from envs.errors import UnknownRenderModeError

    if scenario == "edited":  # a script the package does not ship: refused before the jail starts
        scenario = (ROOT / "scenario_bank" / "scenarios" / BRAKES / "scenario.scenic").read_text() + "\n# edited\n"
    with pytest.raises(UnknownRenderModeError, match=r"^unknown render_mode 'human2' \(did you mean 'human'\?\); "
                                                     r"DV2S-v0 renders 'human' or 'rgb_array', or nothing with None$"):
        gym.make("dv2s_gym:DV2S-v0", scenario=scenario, render_mode="human2")
    gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES, render_mode="rgb_array").close()


def test_a_render_mode_close_to_a_choice_is_refused_before_gymnasium_warns_with_a_suggestion():
    import warnings

    from envs.errors import UnknownRenderModeError

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        message = (r"^unknown render_mode 'rgb' \(did you mean 'rgb_array'\?\); DV2S-v0 renders 'human' or "
                   r"'rgb_array', or nothing with None$")
        with pytest.raises(UnknownRenderModeError, match=message):
            gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES, render_mode="rgb")
    assert [str(w.message) for w in caught] == []


def test_a_list_render_mode_still_collects_the_frames():
    env = gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES, config={"duration": 1.0}, render_mode="rgb_array_list")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frames = env.render()
    assert len(frames) == 2 and frames[0].ndim == 3
    env.close()


def test_a_reward_weights_section_replaces_the_default_whole():
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0, "reward_weights": {"collision": -5}})
    assert env.config["reward_weights"] == {"collision": -5}  # the other terms weigh 0, as the docs say
    env.close()
