"""The bank's check of a script, run inside the jail: compile, sample each seed, run a few seconds."""

from __future__ import annotations

import math
import time
from typing import Any, Dict, List

import envs.scenarios as envs_scenarios
from envs.errors import SceneSamplingError

__all__ = ["check_compiles_and_runs"]


def _idle_action(env: Any) -> Any:
    indexes = getattr(getattr(env.unwrapped, "action_type", None), "actions_indexes", None)
    if isinstance(indexes, dict) and "IDLE" in indexes:
        return indexes["IDLE"]
    return env.action_space.sample()


def check_compiles_and_runs(script: str, name: str, path: str, seeds: List[int], run_seconds: float,
                            max_sample_iterations: int) -> Dict[str, Any]:
    """Compile ``script`` (at ``path``), sample a scene per seed and run ``run_seconds`` of the first.

    Returns ``{"ok": True, "timings": ...}`` or ``{"ok": False, "stage", "error_type", "limit", "message"}``
    for a scene that cannot be sampled; any other failure raises (the worker reports it with its stage).
    """
    from envs.dv2s_env import DV2SEnv, ScenarioRef

    timings: Dict[str, float] = {}
    stage = "compile"
    try:
        start = time.perf_counter()
        compiled = envs_scenarios.compile_scenario(script, name=name, path=path)
        timings["compile"] = time.perf_counter() - start
        stage = "sample"
        start = time.perf_counter()
        for seed in seeds:
            try:
                compiled.sample(int(seed), max_iterations=max_sample_iterations)
            except SceneSamplingError as error:
                return {"ok": False, "stage": "sample", "error_type": "SceneSamplingError", "limit": "iterations",
                        "message": f"no scene sampled in {max_sample_iterations} iterations (seed {seed}): {error}"}
        timings["sample"] = time.perf_counter() - start
        if run_seconds > 0:
            stage = "run"
            start = time.perf_counter()
            env = DV2SEnv(scenario=[ScenarioRef(name=name, path=path, source=script)],
                          config={"duration": run_seconds, "max_sample_iterations": max_sample_iterations},
                          trusted=True)
            steps = 0
            try:
                env.reset(seed=int(seeds[0]) if seeds else 0)
                action = _idle_action(env)
                for _ in range(int(math.ceil(run_seconds * env.config["policy_frequency"])) + 5):
                    _, _, terminated, truncated, _ = env.step(action)
                    steps += 1
                    if terminated or truncated:
                        break
            finally:
                env.close()
            timings["run"] = time.perf_counter() - start
            timings["steps"] = steps
    except BaseException as error:
        error.stage = stage  # the worker reports where it failed
        raise
    return {"ok": True, "stage": "done", "timings": timings}
