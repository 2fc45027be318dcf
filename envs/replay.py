"""Replaying a saved episode trace: the same scene, the same actions, every actor state checked.

Kept apart from :mod:`envs.trace` (which the env itself writes to) so that the
env and the trace format do not import each other.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from envs.dv2s_env import DV2SEnv
from envs.trace import EpisodeTrace, TraceMismatchError
from envs.trace_bounds import check_map, check_values
from scenario_bank.safe_files import read_regular_file
from envs.recording import write_frames
from envs.trace import TraceFileError

MAX_SCRIPT_BYTES = 1024 * 1024
"""The largest script a trace's ``scenario_path`` may name."""

__all__ = ["replay_trace", "replay_trace_file", "TraceMismatchError"]


# a trace file is data from anywhere: its config may choose the episode, not how long a step may run
_BOUNDS = {"simulation_frequency": (1, 1000), "policy_frequency": (1, 1000), "duration": (0, 24 * 3600)}


def trace_config(trace: EpisodeTrace) -> dict:
    """The env config a trace recorded, checked: known keys, bounded frequencies and duration,
    and this machine's step time limit (never the trace's)."""
    defaults = DV2SEnv.default_config()
    if not isinstance(trace.config, dict):
        raise TraceFileError("the trace's config is not a mapping: the trace is damaged or was not written by "
                         "env.save_trace()")
    config = {k: v for k, v in trace.config.items() if k in defaults and k != "step_time_limit"}
    check_values(config)
    for key, (low, high) in _BOUNDS.items():
        value = config.get(key, defaults[key])
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
            raise TraceFileError(f"the trace's config has {key}={value!r}, outside [{low}, {high}]: the trace is "
                             "damaged or was not written by env.save_trace()")
    if config.get("policy_frequency", defaults["policy_frequency"]) > config.get(
            "simulation_frequency", defaults["simulation_frequency"]):
        raise TraceFileError("the trace's config has a policy frequency above its simulation frequency: the trace "
                         "is damaged or was not written by env.save_trace()")
    return config


def replay_trace(trace: EpisodeTrace, *, render_mode: Optional[str] = None, check: bool = True,
                 frames: Optional[List[np.ndarray]] = None):
    """Re-run a traced episode with its actions; returns ``(env, replayed_trace)``.

    With ``check`` (default), raises :class:`TraceMismatchError` at the first step
    whose actor states differ from the trace. When ``frames`` is a list, a rendered
    frame is appended after the reset and after every step (needs ``render_mode="rgb_array"``).
    """
    config = trace_config(trace)
    path = Path(trace.scenario_path) if trace.scenario_path else None
    if path is not None and _script_at(path) == trace.source:
        # The script is still where it was: compile it from there, so that paths in it
        # (`localPath(...)` maps) resolve as they did and the scenario keeps its name.
        env = DV2SEnv(scenario=str(path), config=config, render_mode=render_mode)
    else:
        recorded_map = trace.params.get("map")
        if config.get("map") is None and isinstance(recorded_map, str) and Path(recorded_map).is_file():
            check_map(recorded_map)
            config["map"] = recorded_map  # the map the script resolved, wherever it was relative to
        env = DV2SEnv(scenario=trace.source, config=config, render_mode=render_mode)
    try:
        options = {"scene_seed": trace.scene_seed}
        if trace.fixed_params:
            options["params"] = dict(trace.fixed_params)  # the scene was sampled with these fixed
        env.reset(seed=trace.seed, options=options)
        _compare(trace, env.trace, 0, check)
        if frames is not None:
            frames.append(env.render())
        for i, action in enumerate(trace.actions):
            env.step(_action_from_json(action))
            _compare(trace, env.trace, i + 1, check)
            if frames is not None:
                frames.append(env.render())
    except BaseException:
        env.close()  # an env left open keeps its suspended simulation, and itself, alive
        raise
    return env, env.trace


def replay_trace_file(path: str | os.PathLike, *,
                      video: Optional[str | os.PathLike] = None) -> Tuple[EpisodeTrace, EpisodeTrace]:
    """Replay the trace saved at ``path`` (every actor state checked, see :func:`replay_trace`), writing the
    replayed episode to ``video`` when given; returns ``(saved trace, replayed trace)``."""
    trace = EpisodeTrace.load(path)
    frames = [] if video else None
    env, replayed = replay_trace(trace, render_mode="rgb_array" if video else None, frames=frames)
    fps = env.unwrapped.config["policy_frequency"]
    env.close()
    if video:
        write_frames(video, frames, fps)
    return trace, replayed

def _script_at(path: Path) -> Optional[str]:
    """The text of the script a trace says it ran (``None`` when it is no longer there): a regular ``.scenic``
    file of at most :data:`MAX_SCRIPT_BYTES`, not a symbolic link; anything else is refused."""
    if not isinstance(path, Path) or path.suffix != ".scenic":
        raise TraceFileError(f"the trace's scenario_path {str(path)[:200]!r} is not a .scenic file: the trace is "
                         "damaged or was not written by env.save_trace()")
    try:
        data = read_regular_file(path, MAX_SCRIPT_BYTES)
    except FileNotFoundError:
        return None
    except OSError as error:
        raise TraceFileError(f"the trace's scenario_path {str(path)[:200]!r} cannot be read ({error}); move the "
                         "trace away from it or remove scenario_path from the trace") from None
    except ValueError as error:
        raise TraceFileError(f"the trace's scenario_path is refused: {error}; the trace replays from the script it "
                         "holds once scenario_path is removed from it") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def _action_from_json(action):
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
