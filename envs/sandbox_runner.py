"""The child side of the Scenic sandbox: compile, sample and run one script, report as JSON.

Started by :mod:`scenario_bank.sandbox` as ``python -m envs.sandbox_runner
REQUEST RESULT`` in a child process that already has its CPU-time, memory and
file-size limits, a temporary working directory and a minimal environment.
``REQUEST`` is a JSON file ``{"script", "name", "seeds", "run_seconds",
"max_sample_iterations"}``; the result file is rewritten before each stage
(``{"stage": ...}``) so that a child killed by a limit still says where it was,
and ends as ``{"ok": true, "timings": {...}}`` or ``{"ok": false, "stage",
"error_type", "message"}``. Nothing is printed on stdout that matters.

This module runs untrusted code: it is only ever started by the sandbox, never
imported by the rest of dv2s-gym.
"""

from __future__ import annotations

import json
import math
import sys
import time
from typing import Any, Dict

__all__ = ["main"]


def _write(path: str, data: Dict[str, Any]) -> None:
    from scenario_bank.atomic import atomic_write_json

    atomic_write_json(path, data, fsync=False)


def _idle_action(env: Any) -> Any:
    indexes = getattr(getattr(env.unwrapped, "action_type", None), "actions_indexes", None)
    if isinstance(indexes, dict) and "IDLE" in indexes:
        return indexes["IDLE"]
    return env.action_space.sample()


def _check(request: Dict[str, Any], result_path: str) -> Dict[str, Any]:
    timings: Dict[str, float] = {}
    state: Dict[str, Any] = {"stage": "import", "timings": timings}

    def stage(name: str) -> None:
        state["stage"] = name
        _write(result_path, state)

    stage("import")
    start = time.perf_counter()
    from envs.dv2s_env import DV2SEnv
    from envs.errors import SceneSamplingError
    from envs.scenarios import compile_scenario

    timings["import"] = time.perf_counter() - start
    script, name = request["script"], request.get("name", "<sandboxed>")
    iterations = int(request.get("max_sample_iterations", 2000))
    stage("compile")
    start = time.perf_counter()
    compiled = compile_scenario(script, name=name)
    timings["compile"] = time.perf_counter() - start
    stage("sample")
    start = time.perf_counter()
    for seed in request.get("seeds", [0]):
        try:
            compiled.sample(int(seed), max_iterations=iterations)
        except SceneSamplingError as error:
            return {"ok": False, "stage": "sample", "error_type": "SceneSamplingError", "limit": "iterations",
                    "message": f"no scene sampled in {iterations} iterations (seed {seed}): {error}"}
    timings["sample"] = time.perf_counter() - start
    seconds = float(request.get("run_seconds", 3.0))
    if seconds > 0:
        stage("run")
        start = time.perf_counter()
        env = DV2SEnv(scenario=script, config={"duration": seconds, "max_sample_iterations": iterations})
        try:
            env.reset(seed=int(request.get("seeds", [0])[0]))
            action = _idle_action(env)
            steps = 0
            for _ in range(int(math.ceil(seconds * env.config["policy_frequency"])) + 5):
                _, _, terminated, truncated, _ = env.step(action)
                steps += 1
                if terminated or truncated:
                    break
        finally:
            env.close()
        timings["run"] = time.perf_counter() - start
        timings["steps"] = steps
    timings["peak_virtual_mib"] = _peak_virtual_mib()
    return {"ok": True, "stage": "done", "timings": timings}


def _peak_virtual_mib() -> float:
    """The process's peak address space (what RLIMIT_AS bounds), for sizing the limit."""
    try:
        with open("/proc/self/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("VmPeak:"):
                    return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return -1.0


def main(argv: list) -> int:
    """Run the request in ``argv[0]``; write the result to ``argv[1]``; exit 0 if it was written."""
    if len(argv) != 2:
        print("usage: python -m envs.sandbox_runner REQUEST.json RESULT.json", file=sys.stderr)
        return 2
    request_path, result_path = argv
    with open(request_path, encoding="utf-8") as handle:
        request = json.load(handle)
    try:
        result = _check(request, result_path)
    except MemoryError:
        stage = _read_stage(result_path)
        result = {"ok": False, "stage": stage, "error_type": "MemoryError", "limit": "memory",
                  "message": "ran out of memory"}
    except RecursionError as error:
        result = {"ok": False, "stage": _read_stage(result_path), "error_type": "RecursionError",
                  "limit": "recursion", "message": str(error)}
    except BaseException as error:  # any failure of the script is the result, not a crash of the runner
        message = str(error).strip() or type(error).__name__
        result = {"ok": False, "stage": _read_stage(result_path), "error_type": type(error).__name__,
                  "message": message}
        # Scenic wraps what the script raised; the wrapped error's name stays in the message
        if "MemoryError" in message:
            result.update(limit="memory", message="ran out of memory")
        elif "RecursionError" in message:
            result["limit"] = "recursion"
    _write(result_path, result)
    return 0


def _read_stage(path: str) -> str:
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle).get("stage", "import")
    except (OSError, ValueError):
        return "import"


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
