"""Public CARLA-model scripts of the shipped corpus (tests/data/carla_corpus) run unchanged through the
CARLA façade: a few that use CARLA's props, blueprints, ``AutopilotBehavior``, ``CrossingBehavior`` and
traffic-light helpers, each for 20 steps."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import pytest

import dv2s_gym  # noqa: F401  (registers DV2S-v0)

pytestmark = pytest.mark.usefixtures("in_process_simulator")

CORPUS = Path(__file__).parent / "data" / "carla_corpus" / "scenic3"
SCRIPTS = [
    "Carla_Challenge__carlaChallenge3_static.scenic",  # Trash prop in the lane
    "Carla_Challenge__carlaChallenge8.scenic",
    "NHTSA_pedestrian__pedestrian_01.scenic",
    "trafficLights.scenic",
]


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_corpus_script_runs_in_dv2s(name):
    path = CORPUS / name
    # carlaChallenge8's three placement requirements accept about one draw in 500 (seeds 0-11 need 19 to 2,083
    # draws): the default budget of 2,000 would refuse a few percent of scenes, which is Scenic's sampler, not the
    # facade this test is about
    env = gym.make("dv2s_gym:DV2S-v0", scenario=str(path), config={"max_sample_iterations": 20_000})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.reset(seed=0)
        steps = 0
        for steps in range(1, 21):
            *_, terminated, truncated, _ = env.step(1)
            if terminated or truncated:
                break
    assert steps >= 1 and len(env.unwrapped.trace.states) == steps + 1
    env.close()
