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
from dataclasses import asdict, dataclass, field
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
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        try:
            data = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as error:
            raise ValueError(f"{path} is not a dv2s episode trace: {error}") from None
        version = data.get("version", 0)
        if version > TRACE_VERSION:
            raise ValueError(
                f"{path} was written by a newer dv2s-gym (trace version {version} > {TRACE_VERSION}); upgrade"
            )
        return cls(**data)


def replay_trace(trace: EpisodeTrace, *, render_mode: Optional[str] = None, check: bool = True):
    """Re-run a traced episode with its actions; returns ``(env, replayed_trace)``.

    With ``check`` (default), raises :class:`TraceMismatchError` at the first step
    whose actor states differ from the trace.
    """
    from envs.dv2s_env import DV2SEnv

    config = {k: v for k, v in trace.config.items() if k in DV2SEnv.default_config()}
    env = DV2SEnv(scenario=trace.source, config=config, render_mode=render_mode)
    env.reset(seed=trace.seed, options={"scene_seed": trace.scene_seed})
    _compare(trace, env.trace, 0, check)
    for i, action in enumerate(trace.actions):
        env.step(_action_from_json(action))
        _compare(trace, env.trace, i + 1, check)
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
