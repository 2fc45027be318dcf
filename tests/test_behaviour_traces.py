"""The env's and the built-in drivers' behaviour, recorded: the episode every shipped bank scenario plays.

For every shipped bank scenario, seeds 0 and 1 and the built-in drivers ``rule``, ``idm`` and ``keep_lane``,
``tests/data/behaviour/traces.json`` holds three SHA-256 digests of the episode (``policies.evaluation.run_episode``,
as ``dv2s regress`` and ``dv2s replay`` run it):

- ``trajectory``: the episode's trajectory hash (``policies.evaluation.trajectory_hash``: the actions and every
  actor's state at every step), the hash a regression report holds and a replay must match;
- ``trace``: the whole episode trace (scenario source, seeds, sampled parameters, env config, actions, states,
  events, actor kinds), normalised by ``tests/behaviour_digest.py`` (the checkout's path becomes ``<repo>``);
- ``result``: the episode's outcome as a report records it (``EpisodeResult.to_json``), normalised alike;
- ``observations``: every observation the driver was given, as float32 bytes (the built-in drivers read the
  simulator rather than the observation, so without it a change of what a learnt policy sees would go unseen).

A refactor must leave them all as they are; a change of behaviour meant to be one changes them, and is recorded by
writing them again:

    .venv/bin/python tests/test_behaviour_traces.py --write
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Dict, Optional

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from behaviour_digest import differences, digest, normalise, write_record  # noqa: E402
from policies.evaluation import make_eval_env, run_episode  # noqa: E402
from policies.registry import Policy, load_policy  # noqa: E402

RECORD = ROOT / "tests" / "data" / "behaviour" / "traces.json"
SEEDS = (0, 1)
DRIVERS = ("rule", "idm", "keep_lane")


class _Watched(Policy):
    """A driver that hashes every observation it is given, then acts as the driver does."""

    def __init__(self, driver: Policy) -> None:
        self.driver, self.name, self.seen = driver, driver.name, hashlib.sha256()

    def bind(self, envs) -> None:
        self.driver.bind(envs)

    def reset(self, index: Optional[int] = None) -> None:
        self.driver.reset(index)

    def seed(self, seed: int) -> None:
        self.driver.seed(seed)

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        self.seen.update(np.ascontiguousarray(observations, dtype=np.float32).tobytes())
        return self.driver.act(observations, deterministic)


def _scenarios():
    return sorted(meta.parent.name for meta in (ROOT / "scenario_bank" / "scenarios").glob("*/meta.json"))


def behaviour() -> Dict[str, Dict[str, str]]:
    """``{scenario/driver/seedN: {trajectory, trace, result}}`` for every shipped scenario, driver and seed."""
    places = {str(ROOT): "<repo>"}
    scenarios = _scenarios()
    record = {}
    env = make_eval_env(scenarios)
    try:
        for driver in DRIVERS:
            loaded = load_policy(driver)
            loaded.bind([env])
            for scenario in scenarios:
                for seed in SEEDS:
                    policy = _Watched(loaded)
                    result, trace = run_episode(env, policy, scenario, seed)
                    record[f"{scenario}/{driver}/seed{seed}"] = {
                        "trajectory": result.trajectory_hash,
                        "trace": digest(normalise(asdict(trace), places)),
                        "result": digest(normalise(result.to_json(), places)),
                        "observations": policy.seen.hexdigest(),
                    }
    finally:
        env.close()
    return record


@pytest.mark.slow
def test_every_shipped_scenario_plays_the_episodes_it_played():
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))
    now = behaviour()
    assert len(now) == len(_scenarios()) * len(DRIVERS) * len(SEEDS) >= 150
    assert set(now) == set(recorded), (f"episodes added {sorted(set(now) - set(recorded))[:5]} or gone "
                                       f"{sorted(set(recorded) - set(now))[:5]}: write the record again")
    changed = differences(recorded, now)
    assert not changed, (f"{len(changed)} digest(s) of the episodes differ: {changed[:10]}; if the change is meant, "
                         "record it: python tests/test_behaviour_traces.py --write")


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    write_record(RECORD, behaviour)
