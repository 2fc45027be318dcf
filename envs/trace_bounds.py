"""Bounds on an env config that comes from a file (a saved trace): it is data from anywhere.

A trace records the config of its episode, and replaying it builds that env in the user's process.
Every value it may carry is checked here against the type and size the env can safely build: an
observation of 50 million vehicles, a billion-cell occupancy grid or a huge screen would exhaust
memory, and a class path would import a module. Anything outside raises :class:`TraceConfigError`
naming the key.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, Mapping
import stat

from envs.errors import ACTION_TYPES, OBSERVATION_TYPES
from scenario_bank.errors import DV2SError

__all__ = ["TraceConfigError", "MAX_VEHICLES", "MAX_GRID_CELLS", "MAX_SCREEN", "MAX_MAP_BYTES",
           "check_observation", "check_action", "check_values", "check_map", "check_file_config"]

MAX_VEHICLES = 100
MAX_GRID_CELLS = 100_000
MAX_SCREEN = 4096
MAX_MAP_BYTES = 16 * 1024 * 1024
_MAX_LIST = 64
_MAX_TEXT = 200

OTHER_VEHICLE_TYPES = tuple(f"highway_env.vehicle.behavior.{name}" for name in (
    "IDMVehicle", "LinearVehicle", "AggressiveVehicle", "DefensiveVehicle"))
_DAMAGED = "the trace is damaged or was not written by env.save_trace()"


class TraceConfigError(DV2SError, ValueError):
    """A trace's config holds a value the env cannot safely build."""


def _fail(key: str, value: Any, why: str) -> None:
    shown = repr(value)
    raise TraceConfigError(f"the trace's config has {key}={shown[:80]}{'...' if len(shown) > 80 else ''}: {why}; "
                           f"{_DAMAGED}")


def check_file_config(config: Any, source: str) -> Dict[str, Any]:
    """An env config read from a file other than a trace (a report's or a run folder's ``env_config``),
    bounded like a trace's; the error names ``source``."""
    if config is None:
        return {}
    if not isinstance(config, Mapping):
        raise TraceConfigError(f"{source} has an env_config that is not a mapping; the file is damaged")
    try:
        check_values(config)
    except TraceConfigError as error:
        raise TraceConfigError(str(error).replace("the trace's config", f"the env_config of {source}").replace(
            _DAMAGED, "the file is damaged or was not written by dv2s")) from None
    return dict(config)


def _plain(key: str, value: Any, depth: int = 0) -> None:
    """Only JSON scalars, short strings and short lists of them (one level of nesting)."""
    if value is None or isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        if not math.isfinite(value) or abs(value) > 1e6:
            _fail(key, value, "a number outside [-1e6, 1e6]")
        return
    if isinstance(value, str):
        if len(value) > _MAX_TEXT:
            _fail(key, value, f"a text longer than {_MAX_TEXT} characters")
        return
    if isinstance(value, list) and depth < 2:
        if len(value) > _MAX_LIST:
            _fail(key, value, f"a list of more than {_MAX_LIST} items")
        for item in value:
            _plain(key, item, depth + 1)
        return
    _fail(key, value, "not a number, text or short list")


def _int_in(key: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        _fail(key, value, f"not a whole number in [{low}, {high}]")
    return value


def _number_in(key: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        _fail(key, value, f"not a number in [{low:g}, {high:g}]")
    return float(value)


def check_observation(observation: Any) -> None:
    """An observation config of a shipped type with bounded sizes."""
    if not isinstance(observation, Mapping):
        _fail("observation", observation, "not a mapping")
    kind = observation.get("type")
    if kind not in OBSERVATION_TYPES:
        _fail("observation.type", kind, f"not one of {', '.join(OBSERVATION_TYPES)}")
    for key, value in observation.items():
        if not isinstance(key, str) or len(key) > 64:
            _fail("observation", key, "a key that is not a short text")
        _plain(f"observation.{key}", value)
    if "vehicles_count" in observation:
        _int_in("observation.vehicles_count", observation["vehicles_count"], 1, MAX_VEHICLES)
    if "horizon" in observation:
        _int_in("observation.horizon", observation["horizon"], 1, 100)
    if "cells" in observation:
        _int_in("observation.cells", observation["cells"], 1, 4096)
    if "stack_size" in observation:
        _int_in("observation.stack_size", observation["stack_size"], 1, 16)
    if "observation_shape" in observation:
        shape = observation["observation_shape"]
        if not isinstance(shape, list) or len(shape) != 2:
            _fail("observation.observation_shape", shape, "not [width, height]")
        for side in shape:
            _int_in("observation.observation_shape", side, 1, 1024)
    if kind == "OccupancyGrid" or "grid_size" in observation or "grid_step" in observation:
        _check_grid(observation)


def _check_grid(observation: Mapping[str, Any]) -> None:
    size, step = observation.get("grid_size"), observation.get("grid_step")
    if size is None and step is None:
        return  # highway-env's defaults
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(r, list) and len(r) == 2 for r in size)):
        _fail("observation.grid_size", size, "not [[x_min, x_max], [y_min, y_max]]")
    if not (isinstance(step, list) and len(step) == 2):
        _fail("observation.grid_step", step, "not [x_step, y_step]")
    cells = 1.0
    for (low, high), stride in zip(size, step):
        _number_in("observation.grid_size", low, -1e4, 1e4)
        _number_in("observation.grid_size", high, -1e4, 1e4)
        _number_in("observation.grid_step", stride, 1e-3, 1e4)
        cells *= max(1.0, math.ceil((high - low) / stride))
    if cells > MAX_GRID_CELLS:
        _fail("observation.grid_size", size, f"a grid of {cells:.3g} cells (at most {MAX_GRID_CELLS})")


def check_action(action: Any) -> None:
    """An action config of a shipped type with short lists."""
    if not isinstance(action, Mapping):
        _fail("action", action, "not a mapping")
    if action.get("type") not in ACTION_TYPES:
        _fail("action.type", action.get("type"), f"not one of {', '.join(ACTION_TYPES)}")
    for key, value in action.items():
        if not isinstance(key, str) or len(key) > 64:
            _fail("action", key, "a key that is not a short text")
        _plain(f"action.{key}", value)
    if "actions_per_axis" in action:
        _int_in("action.actions_per_axis", action["actions_per_axis"], 1, 64)


def check_values(config: Mapping[str, Any]) -> None:
    """Every other key a trace's config may carry: its type and range."""
    for key, value in config.items():
        if key == "observation":
            check_observation(value)
        elif key == "action":
            check_action(value)
        elif key == "other_vehicles_type":
            if value not in OTHER_VEHICLE_TYPES:
                _fail(key, value, f"not one of {', '.join(OTHER_VEHICLE_TYPES)}")
        elif key in ("screen_width", "screen_height"):
            _int_in(key, value, 1, MAX_SCREEN)
        elif key == "scaling":
            _number_in(key, value, 0.01, 1000)
        elif key == "max_sample_iterations":
            _int_in(key, value, 1, 100_000)
        elif key == "ego_policy":
            if value not in ("agent", "scenic"):
                _fail(key, value, "not 'agent' or 'scenic'")
        elif key == "manual_control":
            if value is not False:
                _fail(key, value, "manual control is not replayed")
        elif key == "centering_position":
            if not (isinstance(value, list) and len(value) == 2):
                _fail(key, value, "not [x, y]")
            for item in value:
                _number_in(key, item, -10, 10)
        elif key in ("reward_weights",):
            if not isinstance(value, Mapping) or len(value) > _MAX_LIST:
                _fail(key, value, "not a mapping of names to numbers")
            for name, weight in value.items():
                if not isinstance(name, str) or len(name) > 64:
                    _fail(key, name, "a name that is not a short text")
                _number_in(f"{key}.{name}", weight, -1e6, 1e6)
        elif key == "map":
            if value is not None:
                check_map(value)
        else:
            _plain(key, value)
            if isinstance(value, list) and any(isinstance(item, list) for item in value):
                _fail(key, value, "a nested list")


def check_map(value: Any) -> None:
    """A map a trace names: a shipped map name, or a regular ``.xodr`` file (not a symbolic link) of at most
    :data:`MAX_MAP_BYTES`."""
    if not isinstance(value, str) or not value or len(value) > 4096 or "\0" in value:
        _fail("map", value, "not a map name or path")
    if "/" not in value and "\\" not in value and not value.endswith(".xodr"):
        return  # a shipped map's name: resolved among the shipped maps
    path = Path(value)
    if path.suffix != ".xodr":
        _fail("map", value, "not an .xodr file")
    try:
        info = path.lstat()
    except OSError:
        _fail("map", value, "no such file")

    if not stat.S_ISREG(info.st_mode):
        _fail("map", value, "not a regular file (a symbolic link, a folder or a device)")
    if info.st_size > MAX_MAP_BYTES:
        _fail("map", value, f"a file of {info.st_size} bytes (at most {MAX_MAP_BYTES})")


def checked(config: Mapping[str, Any]) -> Dict[str, Any]:
    """``config`` after :func:`check_values`."""
    check_values(config)
    return dict(config)
