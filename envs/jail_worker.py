"""The jailed side of ``DV2S-v0``: one simulation, driven by requests from the user's process.

Started only by :class:`scenario_bank.jail.JailedProcess`: forked by the jail's
zygote, which imported the simulator once (:func:`preload`) and calls :func:`serve`,
or as ``python -m envs.jail_worker IN_FD OUT_FD`` inside bubblewrap (:func:`main`:
import, then serve). It says hello, then answers requests
(:mod:`scenario_bank.jail.wire` messages):

- ``open``: write the scenario texts and the map files sent with them into the
  scratch folder, build a :class:`~envs.dv2s_env.DV2SEnv` over them (the
  allowlist check and the compilation run here) and answer its spaces and config;
- ``reset``, ``step``, ``render``, ``trace``: the env's, with the ego's state;
- ``driver_new``, ``driver_act``: a privileged driver (rule-based, IDM, ...) bound
  to the env next to the simulation: it reads the state here, only its action leaves;
- ``verify``: compile, sample and briefly run a script (the bank's check);
- ``exit``.

Everything it answers is data (:mod:`scenario_bank.jail.wire`); an exception is
answered as ``{"type", "message"}`` and the worker goes on.
"""

from __future__ import annotations

import importlib
import os
import resource
import sys
import time
from dataclasses import asdict
from pathlib import PurePosixPath
from typing import Any, Dict, List, Optional

import numpy as np

import envs.scenarios as envs_scenarios
from envs.sandbox_checks import check_compiles_and_runs
from scenario_bank.jail import wire
from scenario_bank.jail.limits import start_charging_cpu
from scenario_bank.safety import check_script
from scenario_bank.simulator_worker import SCRATCH
from envs.jailed_env import space_to_data

__all__ = ["preload", "serve", "main"]

_DRIVER_MODULES = ("policies.",)


class _Worker:
    def __init__(self) -> None:
        self.env = None
        self.drivers: Dict[int, Any] = {}
        self.folders = 0  # scratch folders used so far

    # ------------------------------------------------------------------ files
    def _write_files(self, index: int, files: Dict[str, Any]) -> str:
        """Write a scenario's files (script folder layout) under the scratch folder; return the folder."""
        folder = os.path.join(SCRATCH, str(index))
        os.makedirs(folder, exist_ok=True)
        for relative, data in (files or {}).items():
            parts = PurePosixPath(relative).parts
            if not parts or PurePosixPath(relative).is_absolute() or ".." in parts:
                raise ValueError(f"file name {relative!r} is not a relative path inside the scenario folder")
            target = os.path.join(folder, *parts)
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with open(target, "wb") as handle:
                handle.write(np.asarray(data, dtype=np.uint8).tobytes())
        return folder

    def open(self, scenarios: List[Dict[str, Any]], config: Optional[dict], render_mode: Optional[str]) -> dict:
        from envs.dv2s_env import DV2SEnv, ScenarioRef

        refs = []
        for index, item in enumerate(scenarios):
            folder = self._write_files(index, item.get("files") or {})
            script = os.path.join(folder, item.get("filename") or "scenario.scenic")
            with open(script, "w", encoding="utf-8") as handle:
                handle.write(item["text"])
            refs.append(ScenarioRef(name=item["name"], path=script, source=item["text"]))
        config = dict(config or {})
        map_file = config.pop("map_file", None)
        if map_file is not None:
            folder = self._write_files(len(scenarios), {map_file["name"]: map_file["data"]})
            config["map"] = os.path.join(folder, map_file["name"])
        if self.env is not None:
            self.env.close()
        self.env = DV2SEnv(scenario=refs, config=config, render_mode=render_mode, trusted=True)
        return {"observation_space": space_to_data(self.env.observation_space),
                "action_space": space_to_data(self.env.action_space),
                "config": _jsonable(self.env.config)}

    # ------------------------------------------------------------------ env
    def _state(self) -> dict:
        env = self.env
        ego = env.vehicle
        return {"steps": int(env.steps), "time": float(env.time),
                "ego": None if ego is None else {
                    "position": [float(ego.position[0]), float(ego.position[1])],
                    "heading": float(ego.heading), "speed": float(ego.speed), "crashed": bool(ego.crashed)}}

    def reset(self, seed: Optional[int], options: Optional[dict]) -> dict:
        obs, info = self.env.reset(seed=seed, options=options)
        return {"obs": obs, "info": _jsonable(info), "state": self._state()}

    def step(self, action: Any) -> dict:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return {"obs": obs, "reward": float(reward), "terminated": bool(terminated), "truncated": bool(truncated),
                "info": _jsonable(info), "state": self._state()}

    def render(self) -> Any:
        return self.env.render()

    def trace(self) -> Optional[dict]:
        trace = self.env.trace
        return None if trace is None else asdict(trace)

    def driver_new(self, class_path: str, args: list, kwargs: dict) -> int:
        module, _, attribute = class_path.partition(":")
        if not module.startswith(_DRIVER_MODULES):
            raise ValueError(f"{class_path!r}: only dv2s-gym's own drivers (policies.*) run next to the simulation")
        cls = getattr(importlib.import_module(module), attribute)
        handle = len(self.drivers) + 1
        self.drivers[handle] = cls(self.env, *args, **kwargs)
        return handle

    def driver_act(self, handle: int) -> int:
        return int(self.drivers[handle].act())

    # ------------------------------------------------------------------ checks
    def verify(self, script: str, name: str, seeds: List[int], run_seconds: float, max_sample_iterations: int,
               files: Optional[dict] = None, filename: Optional[str] = None) -> dict:
        folder = self._write_files(0, files or {})
        path = os.path.join(folder, filename or "scenario.scenic")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(script)
        result = check_compiles_and_runs(script, name, path, seeds, run_seconds, max_sample_iterations)
        if isinstance(result.get("timings"), dict):  # a forked worker is not the user's child: it says its CPU time
            usage = resource.getrusage(resource.RUSAGE_SELF)
            result["timings"]["cpu"] = usage.ru_utime + usage.ru_stime
        return result

    def parameter_ranges(self, name: str, text: str, files: Optional[dict] = None,
                         filename: Optional[str] = None) -> dict:
        self.folders += 1
        folder = self._write_files(1000 + self.folders, files or {})  # apart from the env's scenario folders
        path = os.path.join(folder, filename or "scenario.scenic")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(text)
        compiled = envs_scenarios.compile_scenario(text, name=name, path=path)
        return {k: v.as_dict() for k, v in compiled.parameter_ranges().items()}

    def check(self, script: str, absolute_maps: bool = False) -> list:
        return [_finding(f) for f in check_script(script, absolute_maps=absolute_maps)]


def _jsonable(value: Any, depth: int = 0) -> Any:
    if depth > 40:
        return str(value)[:200]
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value if value.dtype.kind in "biuf" else value.tolist()
    if isinstance(value, dict):
        return {str(k): _jsonable(v, depth + 1) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, depth + 1) for v in value]
    return str(value)[:1000]


def _finding(finding: Any) -> dict:
    return {"line": int(getattr(finding, "line", 0) or 0), "construct": str(getattr(finding, "construct", ""))[:200],
            "reason": str(getattr(finding, "reason", finding))[:500]}


def _error(error: BaseException) -> dict:
    message = str(error).strip() or type(error).__name__
    details: Dict[str, Any] = {"type": type(error).__name__, "message": message[:4000]}
    for name in ("stage", "limit", "path", "line", "construct"):
        value = getattr(error, name, None)
        if isinstance(value, (str, int, float)) or value is None:
            details[name] = value
    if isinstance(error, MemoryError) or "MemoryError" in message:
        details["limit"] = "memory"
    findings = getattr(error, "findings", None)
    if findings:
        details["findings"] = [_finding(f) for f in list(findings)[:50]]
    return details


def preload() -> None:
    """Import the simulator: what starting a worker costs, done once by the zygote for all its workers."""
    import envs.dv2s_env  # noqa: F401


def serve(inbound_fd: int, outbound_fd: int, started: float) -> int:
    """Say hello (``started``: :func:`time.perf_counter` when starting began), then answer requests until
    ``exit`` or the end of the input; the exit status."""
    inbound = os.fdopen(inbound_fd, "rb", buffering=0)
    outbound = os.fdopen(outbound_fd, "wb", buffering=0)
    wire.write_message(outbound, {"ok": True, "value": {"import_seconds": time.perf_counter() - started}})
    worker = _Worker()
    while True:
        try:
            request = wire.read_message(inbound, 512 * 2**20)
        except EOFError:
            return 0
        op = request.pop("op", None) if isinstance(request, dict) else None
        if op == "exit":
            return 0
        handler = getattr(worker, op, None) if isinstance(op, str) and not op.startswith("_") else None
        try:
            if handler is None:
                raise ValueError(f"unknown request {op!r}")
            reply = {"ok": True, "value": handler(**request)}
        except BaseException as error:  # the script's failure is the answer, not the end of the worker
            if isinstance(error, (KeyboardInterrupt, SystemExit)) and not isinstance(error, SystemExit):
                raise
            reply = {"ok": False, "error": _error(error)}
        try:
            wire.write_message(outbound, reply)
        except Exception as error:  # an answer that cannot be sent (e.g. an object) is an error answer
            wire.write_message(outbound, {"ok": False, "error": _error(error)})


def main(argv: List[str]) -> int:
    """``python -m envs.jail_worker IN_FD OUT_FD``: import the simulator, then :func:`serve`."""
    start = time.perf_counter()
    preload()  # before hello, so starting includes it
    start_charging_cpu()
    return serve(int(argv[0]), int(argv[1]), start)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
