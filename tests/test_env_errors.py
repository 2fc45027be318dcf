"""Bad input to ``DV2S-v0``: every mistake gives one clear error naming the problem and the fix."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import dv2s_gym  # noqa: E402,F401  (registers DV2S-v0)
from envs.dv2s_env import DV2SEnv  # noqa: E402
from envs.errors import (  # noqa: E402
    DV2SError,
    InvalidActionError,
    InvalidSeedError,
    ScenarioCompileError,
    SceneSamplingError,
    UnsupportedConstructError,
)
from scenario_bank import UnknownScenarioError  # noqa: E402
from scenario_bank.maps import UnknownMapError  # noqa: E402

BRAKES = "highway_lead_vehicle_brakes"
HEADER = "param map = 'highway_straight'\nmodel scenic.domains.driving.model\n"


def script(tmp_path, text, name="bad.scenic") -> str:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return str(path)


def assert_short_chain(error: BaseException):
    """Raised ``from None``: no chained Scenic/Python internals under the message."""
    assert error.__cause__ is None and error.__suppress_context__


# ----------------------------------------------------------------- scenario names


@pytest.mark.parametrize("typo", ["highway_lead_vehicle_brake", "lead_vehicle_brakes", "Highway_Lead_Vehicle_Brakes"])
def test_unknown_scenario_suggests_near_match(typo):
    with pytest.raises(UnknownScenarioError) as info:
        gym.make("DV2S-v0", scenario=typo)
    message = str(info.value)
    assert repr(typo) in message
    assert f"Did you mean '{BRAKES}'" in message
    assert "tag:<tag>" in message  # says what else can be passed


def test_unknown_name_in_a_list_and_unknown_tag():
    with pytest.raises(UnknownScenarioError, match="urban_pull_back_in"):
        DV2SEnv(scenario=[BRAKES, "urban_pull_back"])
    with pytest.raises(UnknownScenarioError, match=r"tag 'pedestrain'.*Did you mean 'pedestrian'"):
        DV2SEnv(scenario="tag:pedestrain")


def test_scenario_of_the_wrong_type():
    with pytest.raises(TypeError, match="scenario must be"):
        DV2SEnv(scenario=123)
    with pytest.raises(TypeError, match="scenario must be"):
        DV2SEnv(scenario=[BRAKES, 7])


def test_missing_scenic_file(tmp_path):
    missing = tmp_path / "nowhere" / "scenario.scenic"
    with pytest.raises(FileNotFoundError) as info:
        gym.make("DV2S-v0", scenario=str(missing))
    assert str(missing) in str(info.value)
    assert "bank name" in str(info.value)
    with pytest.raises(FileNotFoundError):
        DV2SEnv(scenario="not_here.scenic")


# ------------------------------------------------------------------ compilation


@pytest.mark.slow
def test_syntax_error_names_file_and_line(tmp_path):
    path = script(tmp_path, HEADER + "\nego = new Car at (0, 0\nx = 3\n")
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario=path)
    error = info.value
    assert error.path == path and error.line == 4
    assert f"{path}, line 4" in str(error)
    assert_short_chain(error)


@pytest.mark.slow
def test_error_while_running_the_script_names_file_and_line(tmp_path):
    path = script(tmp_path, HEADER + "\nego = new Car\nlimit = 1 / 0\n")
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario=path)
    assert info.value.line == 5
    assert "ZeroDivisionError" in str(info.value) and f"{path}, line 5" in str(info.value)


def test_syntax_error_names_the_column_and_quotes_the_line(tmp_path):
    path = script(tmp_path, HEADER + "ego = new Car\nlead = new Car ahead of ego by 10 10\n")
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario=path)
    message = str(info.value)
    assert message.startswith(f"{path}, line 4, column 32: Scenic could not compile the scenario: ScenicParseError: ")
    assert message.endswith(" (the line: `lead = new Car ahead of ego by 10 10`; at `10 10`)") and "\n" not in message


def test_compile_error_in_source_text():
    with pytest.raises(ScenarioCompileError, match="<string>, line 3"):
        DV2SEnv(scenario=HEADER + "ego = new Car with speed\n")


def test_map_file_that_does_not_exist(tmp_path):
    missing = tmp_path / "no_such_map.xodr"
    path = script(tmp_path, f"param map = {str(missing)!r}\nmodel scenic.domains.driving.model\nego = new Car\n")
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario=path)
    message = str(info.value)
    assert str(missing) in message and "does not exist" in message
    assert "shipped map name" in message  # the fix
    assert_short_chain(info.value)


@pytest.mark.slow
def test_corrupt_map_file(tmp_path):
    (tmp_path / "broken.xodr").write_text("<OpenDRIVE><header/><road garbage")
    path = script(tmp_path, "param map = localPath('broken.xodr')\nmodel scenic.domains.driving.model\nego = new Car\n")
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario=path)
    message = str(info.value)
    assert str(tmp_path / "broken.xodr") in message
    assert "failed to load" in message and "valid OpenDRIVE" in message


def test_unknown_map_name_suggests_near_match():
    with pytest.raises(ScenarioCompileError, match="Did you mean 'highway_straight'"):
        DV2SEnv(scenario="param map = 'highway_straigt'\nmodel scenic.domains.driving.model\nego = new Car\n")


def test_map_override_that_does_not_exist(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        DV2SEnv(scenario=BRAKES, config={"map": str(tmp_path / "none.xodr")})
    with pytest.raises(UnknownMapError, match="Did you mean 'highway_straight'"):
        DV2SEnv(scenario=BRAKES, config={"map": "highway_straigt"})


def test_script_without_a_map():
    with pytest.raises(ScenarioCompileError) as info:
        DV2SEnv(scenario="model scenic.domains.driving.model\nego = new Car\n")
    message = str(info.value)
    assert "sets no map" in message and "param map" in message and "config={'map'" in message


@pytest.mark.slow
def test_carla_only_construct_at_top_level():
    source = textwrap.dedent(
        """
        param map = 'highway_straight'
        model scenic.simulators.carla.model
        ego = new Car
        cone = new TrafficCone behind ego by 10
        """
    )
    with pytest.raises(UnsupportedConstructError) as info:
        DV2SEnv(scenario=source)
    message = str(info.value)
    assert "`TrafficCone`" in message and "scenic.simulators.carla" in message
    assert info.value.line == 5
    assert_short_chain(info.value)


@pytest.mark.slow
def test_carla_only_action_inside_a_behavior():
    """Names in behaviours are looked up when the simulation runs: still a clear error."""
    source = textwrap.dedent(
        """
        param map = 'highway_straight'
        model scenic.simulators.carla.model
        behavior Autopilot():
            take SetAutopilotAction(True)
        ego = new Car
        other = new Car behind ego by 10, with behavior Autopilot()
        """
    )
    with pytest.raises(UnsupportedConstructError) as info:
        DV2SEnv(scenario=source, config={"duration": 1.0})
    assert "`SetAutopilotAction`" in str(info.value) and "scenic.simulators.carla" in str(info.value)
    assert info.value.line == 5
    # The env of another scenario is not disturbed by the failed one.
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0})
    env.step(1)
    env.close()


@pytest.mark.slow
def test_undefined_name_without_another_simulator():
    with pytest.raises(UnsupportedConstructError, match="`Spaceship` is not defined"):
        DV2SEnv(scenario=HEADER + "ego = new Car\nship = new Spaceship\n")


@pytest.mark.slow
def test_agent_cannot_drive_a_pedestrian_ego():
    source = "param map = 'urban_two_way'\nmodel scenic.domains.driving.model\nego = new Pedestrian on sidewalk\n"
    with pytest.raises(Exception, match="make the ego a Car"):
        DV2SEnv(scenario=source)


# --------------------------------------------------------------------- sampling


@pytest.mark.slow
def test_scene_that_cannot_be_sampled():
    source = HEADER + "ego = new Car with speed Range(0, 10)\nrequire ego.speed > 20\n"
    with pytest.raises(SceneSamplingError) as info:
        DV2SEnv(scenario=source, config={"max_sample_iterations": 20})
    message = str(info.value)
    assert "20 sampling iterations" in message
    assert "requirement on line 4" in message  # the rejecting requirement
    assert "max_sample_iterations" in message  # the fix
    assert isinstance(info.value, DV2SError)


# ---------------------------------------------------------------------- actions


@pytest.mark.parametrize("action", [5, -1, 1.5, None, "LEFT", np.array([1, 2])], ids=repr)
def test_action_outside_discrete_space(action):
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0})
    env.reset(seed=0)
    with pytest.raises(InvalidActionError) as info:
        env.step(action)
    assert "Discrete(5)" in str(info.value) and "env.action_space" in str(info.value)
    # Nothing happened: the episode continues from where it was.
    assert env.time == 0 and len(env.trace.states) == 1
    env.step(np.int64(1))
    assert env.time == pytest.approx(0.2)
    env.close()


@pytest.mark.filterwarnings("ignore:.*Casting input x to numpy array")
@pytest.mark.parametrize(
    "action", [np.array([5.0, 0.0]), [0.0, 0.0, 0.0], np.array([np.nan, 0.0]), 3], ids=repr
)
def test_action_outside_continuous_space(action):
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0, "action": {"type": "ContinuousAction"}})
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match="Box"):
        env.step(action)
    env.step([0.5, -0.5])  # lists and float64 arrays inside the box are fine
    env.step(np.array([0.5, -0.5]))
    env.close()


def test_step_after_close():
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0})
    env.close()
    with pytest.raises(RuntimeError, match=r"reset\(\)"):
        env.step(1)
    env.reset(seed=0)  # and the env can be used again
    env.step(1)
    env.close()


SPINNING_BEHAVIOUR = """\
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Maybe():
    if self.speed < -1:
        take SetThrottleAction(1)
behavior Spin():
    while True:
        do Maybe()
ego = new Car with behavior FollowLaneBehavior(target_speed=10)
other = new Car ahead of ego by 20, with behavior Spin()
"""


@pytest.mark.slow
def test_a_behaviour_looping_without_an_action_is_stopped_and_named(tmp_path):
    """Scenic would spin forever in that step; the env's step_time_limit ends it with the line."""
    import warnings

    from envs.errors import StepTimeoutError

    script = tmp_path / "spin.scenic"
    script.write_text(SPINNING_BEHAVIOUR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Scenic's own StuckBehaviorWarning
        with pytest.raises(StepTimeoutError, match=r"spin\.scenic, line 8: .*`do Maybe\(\)`.*step_time_limit"):
            gym.make("dv2s_gym:DV2S-v0", scenario=str(script), config={"step_time_limit": 2})
        # a Scenic 2 script upgraded in memory is still named by its file and line
        old_style = tmp_path / "spin2.scenic"
        old_style.write_text(SPINNING_BEHAVIOUR.replace("ego = new Car", "ego = Car"))
        with pytest.raises(StepTimeoutError, match=r"spin2\.scenic, line 8: .*`do Maybe\(\)`"):
            gym.make("dv2s_gym:DV2S-v0", scenario=str(old_style), config={"step_time_limit": 2, "upgrade_scenic2": True})
    # the process's profiling timer is left as it was: a normal episode runs after it
    env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_lead_vehicle_brakes", config={"step_time_limit": 2})
    env.reset(seed=0)
    for _ in range(5):
        env.step(1)
    env.close()
    import signal

    assert signal.getitimer(signal.ITIMER_PROF) == (0.0, 0.0)


@pytest.mark.parametrize("seed", [-5, 1.5, "3", True, np.int64(3)])
def test_a_seed_that_is_not_an_integer_at_least_zero_is_refused_naming_it(seed):
    env = gym.make("dv2s_gym:DV2S-v0", scenario=BRAKES)
    with pytest.raises(InvalidSeedError, match=r"reset\(seed=.*\): a seed is an integer >= 0"):
        env.reset(seed=seed)
    assert env.reset(seed=3)[1]["action"] is None  # and the env is still usable
    env.close()


@pytest.mark.parametrize("command", [["run", BRAKES], ["demo"], ["mine"], ["regress", "--policy", "idm"], ["train"],
                                     ["loop"], ["bank", "sample"], ["generate", "a car brakes"], ["convert", "v.mp4"]])
@pytest.mark.parametrize("value", ["-5", "x"])
def test_every_seed_option_refuses_a_bad_seed_naming_the_option(command, value, capsys):
    from dv2s_gym.cli import main

    with pytest.raises(SystemExit) as stop:
        main([*command, "--seed", value])
    assert stop.value.code == 2
    assert f"argument --seed: '{value}' is not a seed: give an integer >= 0" in capsys.readouterr().err


def test_dv2s_run_refuses_a_negative_seed_in_one_line():
    import subprocess

    done = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "run", BRAKES, "--seed", "-5"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == (
        "dv2s run: error: argument --seed: '-5' is not a seed: give an integer >= 0 (e.g. --seed 0; the same seed "
        "gives the same scenes) (see `dv2s run --help`)")
