"""``DV2S-v0`` for untrusted scenarios: a thin client of a simulation running in the jail.

:class:`JailedDV2SEnv` has the interface of :class:`~envs.dv2s_env.DV2SEnv`
(Gymnasium's API, ``config``, ``trace``/``save_trace``, rendering, the ego's
state as ``vehicle``) but compiles, samples and simulates nothing itself: a
jailed worker (:mod:`envs.jail_worker`) does, and sends back observations,
rewards, ``info``, frames and traces as data. Drivers that read the simulator
state (:class:`~policies.state_driver.StateDriver`) run next to the simulation
in the worker and send back only their action.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import gymnasium as gym
import numpy as np

from envs.errors import DV2SError, InvalidActionError, ScenarioCompileError, SceneSamplingError, StepTimeoutError
from envs.errors import ResetNeededError
from envs.config_check import check_config
from envs.errors import UnsupportedConstructError
from envs.trace import EpisodeTrace
import envs.scenarios as envs_scenarios
from scenario_bank.jail import JailedProcess, JailError, JailLimitError, JailLimits, require_jail
from scenario_bank.jail.process import JailRemoteError
from scenario_bank.safe_files import read_in_folder, read_regular_file
from envs.scenarios import ParamRange, read_scenario_file
from scenario_bank.shipped import is_shipped_text
from scenario_bank.maps import list_maps, resolve_map, UnknownMapError
from scenario_bank.safety import UnsafeScenarioError
from scenario_bank.simulator_worker import SCRATCH
from scenario_bank.errors import MissingFileError, UnknownScenarioError, WrongTypeError
from scenario_bank.safe_files import UnsafeInputError

__all__ = ["JailedDV2SEnv", "SpaceDataError", "space_to_data", "data_to_space", "parameter_ranges_of", "MAX_MAP_BYTES"]

MAX_MAP_BYTES = 64 * 2**20  # all map files of one scenario together
MAX_MAP_FILES = 4
_MAP_LINE = re.compile(r"""^[ \t]*param[ \t]+(map|sumo_map)[ \t]*=[ \t]*(localPath[ \t]*\([ \t]*)?(['"])([^'"\n\\]{1,1024})\3""",
                       re.M)


# ---------------------------------------------------------------- spaces as data
class SpaceDataError(DV2SError, ValueError):
    """A space description from the jailed worker is not one :func:`space_to_data` writes. A :class:`ValueError`,
    so code catching that keeps working."""


def space_to_data(space: gym.Space) -> Dict[str, Any]:
    """A Gymnasium space as plain data (Box, Discrete, MultiDiscrete, MultiBinary, Tuple, Dict)."""
    if isinstance(space, gym.spaces.Box):
        return {"type": "Box", "low": space.low, "high": space.high, "dtype": np.dtype(space.dtype).str}
    if isinstance(space, gym.spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, gym.spaces.MultiDiscrete):
        return {"type": "MultiDiscrete", "nvec": space.nvec, "dtype": np.dtype(space.dtype).str}
    if isinstance(space, gym.spaces.MultiBinary):
        return {"type": "MultiBinary", "n": list(np.atleast_1d(space.n))}
    if isinstance(space, gym.spaces.Tuple):
        return {"type": "Tuple", "spaces": [space_to_data(s) for s in space.spaces]}
    if isinstance(space, gym.spaces.Dict):
        return {"type": "Dict", "spaces": {k: space_to_data(s) for k, s in space.spaces.items()}}
    raise WrongTypeError(f"space {space} cannot cross the jail")


def data_to_space(data: Any, depth: int = 0) -> gym.Space:
    """The space :func:`space_to_data` described; raises :class:`SpaceDataError` (a ``ValueError``) on anything
    else."""
    if not isinstance(data, dict) or depth > 8:
        raise SpaceDataError("not a space description")
    kind = data.get("type")
    if kind == "Box":
        low, high = np.asarray(data["low"]), np.asarray(data["high"])
        if low.shape != high.shape or low.size > 10**7:
            raise SpaceDataError("Box bounds disagree")
        return gym.spaces.Box(low=low, high=high, dtype=np.dtype(str(data["dtype"])))
    if kind == "Discrete":
        return gym.spaces.Discrete(int(data["n"]), start=int(data.get("start", 0)))
    if kind == "MultiDiscrete":
        return gym.spaces.MultiDiscrete(np.asarray(data["nvec"]), dtype=np.dtype(str(data["dtype"])))
    if kind == "MultiBinary":
        return gym.spaces.MultiBinary([int(n) for n in data["n"]])
    if kind == "Tuple":
        return gym.spaces.Tuple([data_to_space(s, depth + 1) for s in data["spaces"]])
    if kind == "Dict":
        return gym.spaces.Dict({str(k): data_to_space(s, depth + 1) for k, s in data["spaces"].items()})
    raise SpaceDataError(f"unknown space type {kind!r}")


def _as_space_value(value: Any, space: gym.Space) -> Any:
    if isinstance(space, gym.spaces.Tuple) and isinstance(value, list):
        return tuple(_as_space_value(v, s) for v, s in zip(value, space.spaces))
    if isinstance(space, gym.spaces.Dict) and isinstance(value, dict):
        return {k: _as_space_value(value.get(k), s) for k, s in space.spaces.items()}
    if isinstance(space, gym.spaces.Box) and isinstance(value, np.ndarray) and value.dtype != space.dtype:
        return value.astype(space.dtype)
    return value


# ---------------------------------------------------------------- map files
def map_references(text: str) -> List[Tuple[str, bool]]:
    """``(path, is_local_path)`` of the literal map paths a script names (``param map = ...``)."""
    return [(m.group(4), bool(m.group(2))) for m in _MAP_LINE.finditer(text)]


def _looks_like_map_path(value: str) -> bool:
    return "/" in value or value.lower().endswith(".xodr") or value.startswith(("~", "."))


# ---------------------------------------------------------------- the client
@dataclass
class _Ego:
    """The ego's state after the last reset or step (a copy: the vehicle lives in the jail)."""

    position: np.ndarray
    heading: float
    speed: float
    crashed: bool


_REMOTE_ERRORS = {
    "ScenarioCompileError": ScenarioCompileError,
    "UnsupportedConstructError": UnsupportedConstructError,
    "SceneSamplingError": SceneSamplingError,
    "StepTimeoutError": StepTimeoutError,
    "InvalidActionError": InvalidActionError,
    "UnknownScenarioError": UnknownScenarioError,
    "RecursionError": ScenarioCompileError,
}


class JailedDV2SEnv(gym.Env):
    """``DV2S-v0`` whose simulation runs in the jail; see :class:`~envs.dv2s_env.DV2SEnv` for the arguments.

    Built by ``DV2SEnv(...)`` (and so by ``gym.make("DV2S-v0", ...)``) whenever a
    scenario is not one the package ships; not meant to be built directly.
    ``limits`` sets the worker's CPU, memory and per-request wall-clock limits
    (:class:`~scenario_bank.jail.JailLimits`).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 15}
    runs_in_jail = True

    def __init__(self, refs: Sequence[Any], texts: Sequence[str], config: Optional[dict] = None,
                 render_mode: Optional[str] = None, limits: Optional[JailLimits] = None,
                 default_config: Optional[dict] = None) -> None:
        defaults = dict(default_config or {})
        self.render_mode = render_mode
        self._refs = list(refs)
        self._labels = {ref.name: ref.path for ref in refs}
        user_config = dict(config or {})
        if defaults:
            check_config(user_config, defaults)
        payload = [self._scenario_payload(ref, text) for ref, text in zip(refs, texts)]
        self._host_map = None
        if user_config.get("map") is not None:
            path = resolve_map(user_config["map"])  # the shipped maps' rules and errors, nothing read yet
            if str(user_config["map"]) not in list_maps():  # a file of the user's: its bytes go in, not its path
                user_config["map_file"] = {"name": path.name, "data": np.frombuffer(
                    read_regular_file(path, MAX_MAP_BYTES, follow_symlinks=True), dtype=np.uint8)}
                user_config.pop("map")
                self._host_map = str(path)
        limits = limits or JailLimits.from_env()
        step_limit = user_config.get("step_time_limit", defaults.get("step_time_limit", 60.0))
        if step_limit is not None:
            limits = limits.with_request_seconds(max(float(step_limit), 1.0) * 2 + 5)
        self._limits = limits
        names = ", ".join(ref.name for ref in refs[:3]) + (", ..." if len(refs) > 3 else "")
        self._worker = JailedProcess("envs.jail_worker", limits=limits, name=f"scenario {names}")
        try:
            opened = self._call("open", scenarios=payload, config=user_config,
                                render_mode=None if render_mode is None else "rgb_array",
                                timeout=limits.compile_seconds)
            self.observation_space = data_to_space(opened["observation_space"])
            self.action_space = data_to_space(opened["action_space"])
            self.config = opened["config"] if isinstance(opened["config"], dict) else {}
        except BaseException:
            self._worker.kill()
            raise
        self.vehicle: Optional[_Ego] = None
        self.steps = 0
        self.time = 0.0
        self._trace_cache: Optional[Tuple[int, EpisodeTrace]] = None
        self._window = None

    # ------------------------------------------------------------------ setup
    @staticmethod
    def _scenario_payload(ref: Any, text: str) -> Dict[str, Any]:
        files: Dict[str, np.ndarray] = {}
        folder = Path(ref.path).parent if ref.path else None
        total = 0
        for value, local in map_references(text):
            if folder is None or not _looks_like_map_path(value) or not value.lower().endswith(".xodr"):
                continue
            if os.path.isabs(value) or value.startswith("~"):
                continue  # the jail cannot see it; the allowlist in the jail names the problem
            key = os.path.normpath(value)
            if key in files or key.startswith("..") or key == ".":
                continue  # one copy per file however it is spelt; outside the script's folder: refused there
            if len(files) >= MAX_MAP_FILES:
                raise UnsafeInputError(f"{ref.path}: names more than {MAX_MAP_FILES} map files; a scenario uses one")
            try:
                data = read_in_folder(folder, key, MAX_MAP_BYTES)  # no symbolic link followed at any level
            except FileNotFoundError:
                continue  # Scenic reports the missing map, in the jail
            total += len(data)
            if total > MAX_MAP_BYTES:
                raise UnsafeInputError(f"{ref.path}: its map files add up to over {MAX_MAP_BYTES // 2**20} MiB")
            files[key] = np.frombuffer(data, dtype=np.uint8)
        name = Path(ref.path).name if ref.path else "scenario.scenic"
        return {"name": ref.name, "text": text, "filename": name if name.endswith(".scenic") else "scenario.scenic",
                "files": files}

    def _call(self, op: str, timeout: Optional[float] = None, **payload: Any) -> Any:
        try:
            return self._worker.call(op, timeout=timeout, **payload)
        except JailRemoteError as error:
            cls = _REMOTE_ERRORS.get(error.error_type)
            message = self._host_names(error.plain_message)
            if error.output:
                message += f"\n--- the script's output (last {len(error.output)} characters) ---\n{error.output}"
            if error.error_type == "UnsafeScenarioError":
                unsafe = UnsafeScenarioError.__new__(UnsafeScenarioError)
                ValueError.__init__(unsafe, message)
                unsafe.findings = list(error.details.get("findings") or [])
                raise unsafe from None
            if error.error_type == "UnknownMapError":
                raise UnknownMapError(message) from None
            if error.error_type == "FileNotFoundError":
                raise MissingFileError(message) from None
            if cls is None:
                raise ScenarioCompileError(f"{error.error_type} in the jailed simulation: {message}") from None
            if issubclass(cls, ScenarioCompileError):
                path, line = error.details.get("path"), error.details.get("line")
                raise cls(message, path=self._host_names(path) if isinstance(path, str) else None,
                          line=line if isinstance(line, int) and not isinstance(line, bool) else None) from None
            raise _remote(cls, message) from None
        except JailLimitError as error:
            if error.limit == "wall" and op == "step":
                raise StepTimeoutError(f"{error}; the simulation was stopped") from None
            raise

    def _host_names(self, text: str) -> str:
        """``text`` with the jail's copies of the files named as the user knows them.

        The worker writes scenario ``i`` to ``/tmp/scenarios/i/`` under the script's own file name
        (``scenario.scenic`` for text), its map files beside it, and a ``config["map"]`` file to the
        next folder; each prefix becomes the folder the file came from (a text's script: its name).
        """
        for index, ref in enumerate(self._refs):
            prefix = f"{SCRATCH}/{index}/"
            script = Path(ref.path).name if ref.path and ref.path.endswith(".scenic") else "scenario.scenic"
            text = text.replace(prefix + script, ref.path or ref.name)
            if ref.path:
                text = text.replace(prefix, str(Path(ref.path).parent) + "/")
        if self._host_map is not None:
            text = text.replace(f"{SCRATCH}/{len(self._refs)}/", str(Path(self._host_map).parent) + "/")
        return text

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """Sample a new scene in the jail and start it; see :meth:`DV2SEnv.reset`."""
        super().reset(seed=seed)
        result = self._call("reset", seed=seed, options=dict(options or {}))
        self._after(result)
        return _as_space_value(result["obs"], self.observation_space), self._info(result)

    def step(self, action):
        """Apply ``action`` for one policy period; Gymnasium's 5-tuple."""
        if self.vehicle is None:
            raise ResetNeededError("step() was called before reset(): call reset() to start an episode first")
        if isinstance(action, np.ndarray) and action.dtype.kind not in "biuf":
            raise InvalidActionError(f"action {action!r} is outside the action space {self.action_space}")
        if isinstance(action, (np.integer,)):
            action = int(action)
        result = self._call("step", action=action)
        self._after(result)
        return (_as_space_value(result["obs"], self.observation_space), float(result["reward"]),
                bool(result["terminated"]), bool(result["truncated"]), self._info(result))

    def _after(self, result: Dict[str, Any]) -> None:
        state = result.get("state") or {}
        ego = state.get("ego")
        self.vehicle = None if ego is None else _Ego(np.asarray(ego["position"], dtype=float), float(ego["heading"]),
                                                     float(ego["speed"]), bool(ego["crashed"]))
        self.steps = int(state.get("steps", 0))
        self.time = float(state.get("time", 0.0))
        self._trace_cache = None

    def _info(self, result: Dict[str, Any]) -> dict:
        info = result.get("info")
        if not isinstance(info, dict):
            info = {}
        if isinstance(info.get("params"), dict):
            self._host_map_param(info["params"])
        return info

    def _host_map_param(self, params: Dict[str, Any]) -> None:
        """``params["map"]``, the file Scenic resolved, named as the user's file instead of the jail's copy."""
        if isinstance(params.get("map"), str):
            params["map"] = self._host_names(params["map"])

    def render(self):
        """A frame (``rgb_array``), or the frame drawn in a window (``human``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        frame = self._call("render")
        frame = None if frame is None else np.asarray(frame, dtype=np.uint8)
        if self.render_mode == "human" and frame is not None:
            self._show(frame)
            return None
        return frame

    def _show(self, frame: np.ndarray) -> None:
        import pygame

        if self._window is None:
            pygame.init()
            self._window = pygame.display.set_mode((frame.shape[1], frame.shape[0]))
            pygame.display.set_caption("DV2S-v0")
        pygame.surfarray.blit_array(self._window, np.transpose(frame, (1, 0, 2)))
        pygame.display.flip()
        pygame.event.pump()

    # ------------------------------------------------------------------ traces
    @property
    def unwrapped(self) -> "JailedDV2SEnv":
        return self

    @property
    def trace(self) -> Optional[EpisodeTrace]:
        """The current episode's trace, fetched from the jail (cached until the next step)."""
        if self._trace_cache is not None and self._trace_cache[0] == self.steps:
            return self._trace_cache[1]
        data = self._call("trace")
        if data is None:
            return None
        trace = EpisodeTrace.from_dict(data, "the jailed simulation's trace")
        trace.scenario_path = self._labels.get(trace.scenario, trace.scenario_path)
        self._host_map_param(trace.params)
        self._trace_cache = (self.steps, trace)
        return trace

    def save_trace(self, path: Union[str, os.PathLike]) -> Path:
        """Write the current episode's trace to ``path`` (JSON, ``.gz`` compresses)."""
        trace = self.trace
        if trace is None:
            raise ResetNeededError("no episode to save: call reset() (and step()) first")
        return trace.save(path)

    # ------------------------------------------------------------------ privileged drivers
    def driver_new(self, driver_class: type, args: Sequence[Any], kwargs: Dict[str, Any]) -> int:
        """Bind a :class:`~policies.state_driver.StateDriver` class to the simulation in the jail; its handle."""
        path = f"{driver_class.__module__}:{driver_class.__qualname__}"
        return int(self._call("driver_new", class_path=path, args=list(args), kwargs=dict(kwargs)))

    def driver_act(self, handle: int) -> int:
        """The action of the driver ``handle`` for the current state."""
        return int(self._call("driver_act", handle=handle))

    # ------------------------------------------------------------------ cleanup
    @property
    def worker_pid(self) -> Optional[int]:
        """The jailed worker's process id on this machine (bubblewrap's, when bubblewrap started it)."""
        return self._worker.pid

    def close(self) -> None:
        """Stop the jailed simulation and close the window."""
        worker = getattr(self, "_worker", None)
        if worker is not None:
            worker.close()
        if getattr(self, "_window", None) is not None:
            import pygame

            pygame.display.quit()
            self._window = None

    def __del__(self) -> None:
        try:
            worker = getattr(self, "_worker", None)
            if worker is not None:
                worker.kill()
        except Exception:
            pass


def parameter_ranges_of(refs: Sequence[Any]) -> Dict[str, Dict[str, Any]]:
    """``{scenario: {param: ParamRange}}`` of each scenario's random global parameters.

    The package's own scripts are compiled here; every other script in one jailed
    worker, which sends back only the ranges (checked: kinds, numbers, constants).
    """
    result: Dict[str, Dict[str, Any]] = {}
    untrusted = []
    for ref in refs:
        text = ref.source if ref.source is not None else read_scenario_file(ref.path)
        if is_shipped_text(text):
            result[ref.name] = envs_scenarios.compile_scenario(text, name=ref.name, path=ref.path).parameter_ranges()
        else:
            untrusted.append((ref, text))
    if untrusted:
        require_jail(f"scenario {untrusted[0][0].name!r}")
        with JailedProcess("envs.jail_worker", name=f"scenario {untrusted[0][0].name!r}") as worker:
            for ref, text in untrusted:
                payload = JailedDV2SEnv._scenario_payload(ref, text)
                data = worker.call("parameter_ranges", **payload)
                result[ref.name] = {str(k): _param_range(ParamRange, v) for k, v in (data or {}).items()}
    return {ref.name: result[ref.name] for ref in refs}


def _param_range(cls: type, data: Any) -> Any:
    if not isinstance(data, dict) or data.get("kind") not in ("continuous", "integer", "choice"):
        raise JailError("the jailed worker sent an invalid parameter range")
    if data["kind"] == "choice":
        values = data.get("values")
        if not isinstance(values, list) or not all(isinstance(v, (str, int, float, bool)) for v in values):
            raise JailError("the jailed worker sent an invalid parameter range")
        return cls("choice", values=tuple(values))
    low, high = data.get("low"), data.get("high")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (low, high)):
        raise JailError("the jailed worker sent an invalid parameter range")
    return cls(data["kind"], int(low) if data["kind"] == "integer" else float(low),
               int(high) if data["kind"] == "integer" else float(high))


def _remote(cls: type, message: str) -> BaseException:
    try:
        return cls(message)
    except TypeError:  # an error class with a richer constructor
        error = DV2SError(message)
        return error

