"""Episode traces: everything needed to look at an episode again or replay it exactly.

A trace holds the scenario (name, source text), the seeds, the sampled scene
parameters, the env config, the agent's actions, the state of every actor after
every step (highway-env frame: x, y, heading, speed) and the events.
Replaying re-runs the same scene with the same actions and checks that every
state matches.
"""

from __future__ import annotations

import gzip
import json
import os
import zlib
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

__all__ = ["EpisodeTrace", "actor_state", "replay_trace", "TraceMismatchError"]

TRACE_VERSION = 1


def actor_state(vehicle) -> List[float]:
    """``[x, y, heading, speed]`` of a highway-env object (full precision)."""
    return [float(vehicle.position[0]), float(vehicle.position[1]), float(vehicle.heading), float(vehicle.speed)]


class TraceMismatchError(AssertionError):
    """A replay diverged from its trace."""


@dataclass
class EpisodeTrace:
    """One episode, step by step."""

    scenario: str
    source: str
    seed: Optional[int]
    scene_seed: int
    params: Dict[str, Any]
    config: Dict[str, Any]
    scenario_path: Optional[str] = None
    actions: List[Any] = field(default_factory=list)
    states: List[Dict[str, List[float]]] = field(default_factory=list)
    events: List[Dict[str, Any]] = field(default_factory=list)
    kinds: Dict[str, str] = field(default_factory=dict)
    """Actor name -> element-vocabulary type (ego, car, truck, pedestrian, obstacle)."""
    version: int = TRACE_VERSION

    def save(self, path: Union[str, os.PathLike]) -> Path:
        """Write the trace as JSON (gzip-compressed when ``path`` ends in ``.gz``); atomic."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        data = json.dumps(asdict(self)).encode("utf-8")
        if path.suffix == ".gz":
            data = gzip.compress(data, mtime=0)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        try:
            with open(tmp, "wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
        finally:
            if tmp.exists():
                tmp.unlink()
        return path

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "EpisodeTrace":
        """Read a trace written by :meth:`save`."""
        raw = Path(path).read_bytes()
        try:
            if raw[:2] == b"\x1f\x8b":
                raw = gzip.decompress(raw)
            data = json.loads(raw.decode("utf-8"))
        except (OSError, EOFError, zlib.error, UnicodeDecodeError, json.JSONDecodeError) as error:
            raise ValueError(
                f"{path} is not a dv2s episode trace (corrupt or truncated file: {error}); "
                "save it again with env.save_trace()"
            ) from None
        names = {f.name for f in fields(cls)}
        required = {f.name for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING}
        if not isinstance(data, dict) or not required <= data.keys():
            missing = sorted(required - data.keys()) if isinstance(data, dict) else sorted(required)
            raise ValueError(
                f"{path} is not a dv2s episode trace: missing fields {', '.join(missing)}; "
                "traces are written by env.save_trace()"
            )
        version = data.get("version", 0)
        if version > TRACE_VERSION:
            raise ValueError(
                f"{path} was written by a newer dv2s-gym (trace version {version} > {TRACE_VERSION}); upgrade"
            )
        return cls(**{k: v for k, v in data.items() if k in names})


def replay_trace(trace: EpisodeTrace, *, render_mode: Optional[str] = None, check: bool = True):
    """Re-run a traced episode with its actions; returns ``(env, replayed_trace)``.

    With ``check`` (default), raises :class:`TraceMismatchError` at the first step
    whose actor states differ from the trace.
    """
    from envs.dv2s_env import DV2SEnv

    config = {k: v for k, v in trace.config.items() if k in DV2SEnv.default_config()}
    path = Path(trace.scenario_path) if trace.scenario_path else None
    if path is not None and path.is_file() and path.read_text(encoding="utf-8") == trace.source:
        # The script is still where it was: compile it from there, so that paths in it
        # (`localPath(...)` maps) resolve as they did and the scenario keeps its name.
        env = DV2SEnv(scenario=str(path), config=config, render_mode=render_mode)
    else:
        recorded_map = trace.params.get("map")
        if config.get("map") is None and isinstance(recorded_map, str) and Path(recorded_map).is_file():
            config["map"] = recorded_map  # the map the script resolved, wherever it was relative to
        env = DV2SEnv(scenario=trace.source, config=config, render_mode=render_mode)
    try:
        env.reset(seed=trace.seed, options={"scene_seed": trace.scene_seed})
        _compare(trace, env.trace, 0, check)
        for i, action in enumerate(trace.actions):
            env.step(_action_from_json(action))
            _compare(trace, env.trace, i + 1, check)
    except BaseException:
        env.close()  # an env left open keeps its suspended simulation, and itself, alive
        raise
    return env, env.trace


def _action_from_json(action):
    import numpy as np

    if isinstance(action, list):
        return np.asarray(action, dtype=np.float32)
    return action


def _compare(expected: EpisodeTrace, actual: EpisodeTrace, step: int, check: bool) -> None:
    if not check:
        return
    if expected.states[step] != actual.states[step]:
        raise TraceMismatchError(
            f"replay of {expected.scenario!r} diverged at step {step}: "
            f"expected {expected.states[step]}, got {actual.states[step]}"
        )
