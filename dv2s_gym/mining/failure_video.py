"""A mined failure as a bird's-eye video of the seconds before and through it, plus its trace.

The failure is re-run from its episode record (scenario, seed, sampled parameters) with the
same deterministic policy in an env that renders off-screen; the re-run must reproduce the
record's trajectory hash, or :class:`FailureReplayError` says the replay diverged. A saved
trace (:class:`~envs.trace.EpisodeTrace` or its file) is replayed with its own actions instead
(:func:`envs.replay.replay_trace`, every actor state checked). The frames from ``before``
seconds before the failure through ``after`` seconds after it are written as a VP8 ``.webm``
(:class:`envs.recording.VideoWriter`) at the policy frequency, in the style the ``bev`` Driving
Record Analyzer reads (ego-centred, north up, 5.5 px/m).

A ``stall`` failure's time is when the ego starts standing, so its clip covers the stall: from
``before`` seconds before it starts through its last standing frame (at most ``stall_seconds``, the
monitor's stall duration, after its start), then ``after`` seconds; every other failure class keeps the
window around its failure time.

Episodes usually end at the collision (``terminate_on_collision``); to show ``after`` seconds
past it, the policy keeps driving the re-run env after the episode ended. Those extra steps
are not part of the episode: the trajectory hash is taken, and the trace saved, before them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Dict, List, Mapping, NamedTuple, Optional, Tuple, Union

import gymnasium as gym
import numpy as np

from dv2s_gym.mining.monitors import DEFAULT_STALL_SECONDS, STALL_SPEED
from envs.errors import DV2SError
from envs.recording import VideoWriter
from envs.safety_metrics import path_is_free
from envs.trace import EpisodeTrace, TraceMismatchError
from policies.evaluation import run_episode, make_eval_env
from policies.registry import load_policy

__all__ = ["FailureReplayError", "FailureVideo", "VIDEO_CONFIG", "VideoSettings", "failure_step",
           "record_failure_video", "rerun_failure", "stall_end", "write_failure_video", "write_script_episode_video"]

VIDEO_CONFIG: Dict[str, Any] = {"screen_width": 480, "screen_height": 480, "scaling": 5.5,
                                "offscreen_rendering": True, "show_trajectories": False}
"""Rendering settings of failure videos (those of the shipped evaluation clips the ``bev`` DRA was built on).
They change only the pixels, never the trajectory."""

PathLike = Union[str, os.PathLike]


class FailureReplayError(DV2SError, ValueError):
    """A failure that cannot be re-run: a malformed record, or a replay that diverged from it."""


def _frequency(config: Mapping[str, Any]) -> float:
    return float(config.get("policy_frequency") or 5)


def failure_step(failure: Optional[Mapping[str, Any]], steps: int, frequency: float) -> int:
    """The frame index (0 = the reset) showing the failure: the failure's ``step`` when given, else the
    frame nearest its ``time`` (as the miner's monitors count steps); the last frame when neither is
    known. Clipped to ``[0, steps]``."""
    failure = failure or {}
    if failure.get("step") is not None:
        k = int(failure["step"])
    elif failure.get("time") is not None:
        k = int(round(float(failure["time"]) * frequency))
    else:
        k = steps
    return max(0, min(steps, k))


def stall_end(trace, start: int, max_frames: int) -> int:
    """The last frame (0 = the reset) of the stall starting at frame ``start``: the ego stands (speed below
    the monitors' stall speed) with a free path ahead (:func:`envs.safety_metrics.path_is_free`) from
    ``start`` through it; at most ``start + max_frames - 1``, at least ``start``, within the trace."""
    last = start
    for k in range(start, min(len(trace.states), start + max(1, int(max_frames)))):
        states = trace.states[k]
        ego = states.get("ego")
        if ego is None or ego[3] >= STALL_SPEED or not path_is_free(
                ego, (state for name, state in states.items() if name != "ego")):
            break
        last = k
    return last


def _trace_failure(trace) -> Optional[Dict[str, Any]]:
    """The first failure event of a trace (a collision involving the ego, or leaving the road)."""
    for event in trace.events:
        if event.get("kind") == "collision" and "ego" in event.get("actors", []):
            return {"type": "collision", "time": float(event["time"])}
        if event.get("kind") == "off_road":
            return {"type": "off_road", "time": float(event["time"])}
    return None


def _check_record(record: Mapping[str, Any]) -> None:
    missing = [key for key in ("scenario", "seed") if record.get(key) is None]
    if not (record.get("result") or {}).get("trajectory_hash"):
        missing.append("result.trajectory_hash")
    if missing:
        raise FailureReplayError(f"the failure record lacks {', '.join(missing)}; pass an episode record of "
                                 "episodes.jsonl (or a saved episode trace)")


def _run_episode(env, policy, scenario: str, seed: int, params: Mapping[str, Any], frames):
    return run_episode(env, policy, scenario, seed, frames=frames, params=dict(params) or None)


class _LastObservation(gym.Wrapper):
    """The env, keeping the observation its last reset or step returned (:attr:`observation`): what the policy
    acts on past the episode's end. Reading it from the simulator instead would need the in-process env; a
    jailed env (:class:`~envs.jailed_env.JailedDV2SEnv`) only sends observations back from reset and step."""

    observation: Any = None

    def reset(self, **kwargs):
        self.observation, info = self.env.reset(**kwargs)
        return self.observation, info

    def step(self, action):
        result = self.env.step(action)
        self.observation = result[0]
        return result


def rerun_failure(record: Mapping[str, Any], *, policy: Any, bank_dir: Optional[PathLike] = None,
                  env_config: Optional[Mapping[str, Any]] = None, render: bool = False,
                  extra_steps: int = 0) -> Tuple[Any, Any, List[np.ndarray]]:
    """Re-run an episode record with ``policy`` (a spec or a :class:`~policies.registry.Policy`).

    Returns ``(EpisodeResult, EpisodeTrace, frames)``; frames (when ``render``) hold the reset and every
    step, then ``extra_steps`` more steps driven past the episode's end. Raises
    :class:`FailureReplayError` when the trajectory hash differs from the record's.
    """
    _check_record(record)
    config = dict(env_config or {})
    if render:
        config.update(VIDEO_CONFIG)
    env = make_eval_env([record["scenario"]], config=config, bank_dir=str(bank_dir) if bank_dir else None,
                        render_mode="rgb_array" if render else None)
    expected = record["result"]["trajectory_hash"]
    scene = _Scene(record["scenario"], int(record["seed"]), record.get("params") or {})
    return _checked_run(env, policy, scene, render, extra_steps, expected,
                        lambda got: (f"the replay of episode {record.get('index', '?')} ({record['scenario']}, seed "
                                     f"{record['seed']}) diverged: trajectory hash {got[:12]} != recorded "
                                     f"{expected[:12]}; re-run with the mining run's policy, env config and "
                                     "dv2s-gym version"))


class _Scene(NamedTuple):
    """The scene an episode runs: the scenario's name, the env seed and the script's sampled parameters."""

    scenario: str
    seed: int
    params: Mapping[str, Any]


def _checked_run(env, policy: Any, scene: _Scene, render: bool, extra_steps: int, expected: Optional[str],
                 diverged) -> Tuple[Any, Any, List[np.ndarray]]:
    """One episode of ``policy`` on ``env`` (closed afterwards) in ``scene``, its trajectory hash checked against
    ``expected`` (``diverged(hash)`` is the error's message), then ``extra_steps`` rendered steps past its end."""
    try:
        bound = load_policy(policy)
        bound.bind([env])
        frames: Optional[List[np.ndarray]] = [] if render else None
        watched = _LastObservation(env)
        result, trace = _run_episode(watched, bound, scene.scenario, scene.seed, scene.params, frames)
        if expected is not None and result.trajectory_hash != expected:
            raise FailureReplayError(diverged(result.trajectory_hash))
        trace = dataclasses.replace(trace, actions=list(trace.actions), states=list(trace.states),
                                    events=list(trace.events))  # the episode as recorded, before extra steps
        for _ in range(extra_steps if render else 0):
            action = bound.act(np.asarray(watched.observation)[None], deterministic=True)[0]
            watched.step(action)
            frames.append(env.render())
        return result, trace, frames or []
    finally:
        env.close()


def _replay_trace_frames(trace) -> List[np.ndarray]:
    from envs.replay import replay_trace

    config = {**trace.config, **VIDEO_CONFIG}
    frames: List[np.ndarray] = []
    try:
        env, _ = replay_trace(dataclasses.replace(trace, config=config), render_mode="rgb_array", frames=frames)
    except TraceMismatchError as error:
        raise FailureReplayError(f"the replay of the trace diverged: {str(error)[:300]}") from None
    env.close()
    return frames


@dataclasses.dataclass
class FailureVideo:
    """What :func:`write_failure_video` wrote and saw: the video and trace paths, the frame window
    ``[first, last]`` (frame indices, 0 = the reset), the failure's frame, the frames per second,
    and the episode's :class:`~policies.evaluation.EpisodeResult` (None for a trace replay) and trace."""

    path: Path
    trace_path: Optional[Path]
    first: int
    last: int
    failure_frame: int
    fps: float
    result: Any
    trace: Any

    @property
    def frames(self) -> int:
        return self.last - self.first + 1


@dataclasses.dataclass(frozen=True)
class VideoSettings:
    """How :func:`write_failure_video` re-runs and films a failure: the deterministic ``policy`` that failed (not
    needed to replay a trace), the bank holding the scenario (``bank_dir``; default the shipped bank), the episode's
    ``env_config``, the seconds of video ``before`` and ``after`` the failure, and ``stall_seconds``, the longest
    stall a clip covers (default the monitors' ``DEFAULT_STALL_SECONDS``)."""

    policy: Any = None
    bank_dir: Optional[PathLike] = None
    env_config: Optional[Mapping[str, Any]] = None
    before: float = 4.0
    after: float = 1.0
    stall_seconds: Optional[float] = None

    @classmethod
    def of(cls, settings: Optional["VideoSettings"], options: Mapping[str, Any]) -> "VideoSettings":
        """``settings`` (default: the defaults) with ``options`` (its fields by name) on top."""
        return dataclasses.replace(settings or cls(), **dict(options))


def record_failure_video(record_or_trace: Union[Mapping[str, Any], Any, PathLike], out_path: PathLike,
                         settings: Optional[VideoSettings] = None, *, trace_path: Optional[PathLike] = None,
                         **options: Any) -> Path:
    """Write the bird's-eye video of a failure (``.webm``) and its trace; returns the video's path.

    ``record_or_trace`` is an episode record of the miner (re-run with the settings' ``policy``, which must be the
    deterministic policy that failed, and checked against the record's trajectory hash) or an
    :class:`~envs.trace.EpisodeTrace` or trace file (replayed with its recorded actions; ``policy`` is
    not needed, and the clip cannot run past the trace's end). ``settings`` (:class:`VideoSettings`), or its
    fields given one by one as keywords (``policy=``, ``before=``...). The clip holds the frames from
    ``before`` seconds before the failure (``record["failure"]``; for a trace, its first ego
    collision or off-road event) through ``after`` seconds after it, at the policy frequency:
    ``round(before * f) + round(after * f) + 1`` frames unless the episode started less than
    ``before`` seconds before the failure. A record's ``stall`` covers the stall: the window runs from
    ``before`` seconds before its start through its last standing frame (:func:`stall_end`, at most
    ``stall_seconds`` after the start; default the monitors' ``DEFAULT_STALL_SECONDS``) plus ``after``
    seconds. The trace is saved to ``trace_path`` (default ``trace.json.gz`` beside the video).
    """
    return write_failure_video(record_or_trace, out_path, settings, trace_path=trace_path, **options).path


def _write_window(out_path: Path, frames: List[np.ndarray], trace, k: int, frequency: float,
                  stall_seconds: Optional[float], settings: VideoSettings) -> Tuple[int, int]:
    """Write the frames (``frequency`` per second) from ``before`` seconds before frame ``k`` to ``after`` seconds
    after it (after the stall's end when ``stall_seconds`` is given) to ``out_path``. Returns the first and last
    frame written."""
    start = max(0, k - int(round(settings.before * frequency)))
    last = stall_end(trace, k, int(math.ceil(stall_seconds * frequency))) if stall_seconds is not None else k
    end = min(len(frames) - 1, last + int(round(settings.after * frequency)))
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with VideoWriter(out_path, fps=frequency) as video:
        for frame in frames[start:end + 1]:
            video.write(frame)
    return start, end


def write_failure_video(record_or_trace: Union[Mapping[str, Any], Any, PathLike], out_path: PathLike,
                        settings: Optional[VideoSettings] = None, *, trace_path: Optional[PathLike] = None,
                        **options: Any) -> FailureVideo:
    """:func:`record_failure_video`, returning a :class:`FailureVideo` (window, result, trace)."""
    settings = VideoSettings.of(settings, options)
    stall_seconds = _check_window(settings)
    out_path = Path(out_path)
    trace_path = Path(trace_path) if trace_path is not None else out_path.parent / "trace.json.gz"
    if isinstance(record_or_trace, Mapping):
        clip = _record_clip(record_or_trace, settings, stall_seconds)
    else:
        clip = _trace_clip(record_or_trace)
    frames, result, trace, frequency, k, stall = clip
    start, end = _write_window(out_path, frames, trace, k, frequency, stall_seconds if stall else None,
                               settings)
    trace.save(trace_path)
    return FailureVideo(out_path, trace_path, start, end, k, frequency, result, trace)


def _check_window(settings: VideoSettings) -> float:
    """The settings' ``stall_seconds`` (its default filled in), once ``before``, ``after`` and it are checked."""
    if settings.before < 0 or settings.after < 0:
        raise FailureReplayError(f"before and after must be >= 0 seconds, not {settings.before} and {settings.after}")
    stall_seconds = DEFAULT_STALL_SECONDS if settings.stall_seconds is None else float(settings.stall_seconds)
    if not stall_seconds > 0:
        raise FailureReplayError(f"stall_seconds must be > 0, not {stall_seconds}")
    return stall_seconds


def _record_clip(record: Mapping[str, Any], settings: VideoSettings, stall_seconds: float) -> tuple:
    """``(frames, result, trace, frequency, failure frame, stall)`` of an episode record, re-run far enough past
    its end to show ``after`` seconds (and a stall's standing frames) past the failure."""
    if settings.policy is None:
        raise FailureReplayError("re-running a failure record needs the policy that failed (policy=...)")
    frequency = _frequency({**VIDEO_CONFIG, **dict(settings.env_config or {})})
    steps = int((record.get("result") or {}).get("steps") or 0)
    k = failure_step(record.get("failure"), steps, frequency)
    stall = (record.get("failure") or {}).get("type") == "stall"
    span = int(math.ceil(stall_seconds * frequency)) if stall else 0  # an upper bound of the stall's frames
    end = k + span + int(round(settings.after * frequency))
    result, trace, frames = rerun_failure(record, policy=settings.policy, bank_dir=settings.bank_dir,
                                          env_config=settings.env_config, render=True,
                                          extra_steps=max(0, end - steps))
    frequency = _frequency(trace.config)
    k = failure_step(record.get("failure"), len(trace.actions), frequency)
    return frames, result, trace, frequency, k, stall


def _trace_clip(source: Any) -> tuple:
    """``(frames, None, trace, frequency, failure frame, False)`` of a saved trace (or its file), replayed with its
    recorded actions."""
    trace = source if isinstance(source, EpisodeTrace) else None
    if trace is None:
        try:
            trace = EpisodeTrace.load(source)
        except (OSError, ValueError) as error:
            raise FailureReplayError(f"cannot read the failure trace {source}: {error}") from None
    frames = _replay_trace_frames(trace)
    frequency = _frequency(trace.config)
    return frames, None, trace, frequency, failure_step(_trace_failure(trace), len(trace.actions), frequency), False


def write_script_episode_video(script_path: PathLike, episode: Mapping[str, Any], out_path: PathLike,
                               settings: Optional[VideoSettings] = None, *, centre: Optional[int] = None,
                               scenario: Optional[str] = None, **options: Any) -> FailureVideo:
    """Run the settings' ``policy`` on a scene of a Scenic script file (a converted script; in the jail unless the
    package ships it) with the settings' ``env_config``, rendered as failure videos are (:data:`VIDEO_CONFIG`,
    which changes only the pixels), and write the clip of one ``episode`` that already ran on it: its ``seed``,
    ``steps`` (its length), ``failure`` (as the monitors found it: its ``step`` or ``time`` and ``type``; ``None``
    when it drove safely) and ``trajectory_hash`` (checked when present: a rendered run that diverges raises
    :class:`FailureReplayError`). The clip is the window from ``before`` seconds before to ``after`` seconds
    after the failure (a stall's window covers the stall), or, when it did not fail, around frame ``centre``
    (e.g. where the original failure happened; default the episode's end), at the policy frequency; past the
    episode's end the policy drives on.
    ``scenario``: the name the episode ran under (default the script's folder name for a ``scenario.scenic``, else
    its stem). No trace is written (:attr:`FailureVideo.trace_path` is ``None``)."""
    from envs.dv2s_env import DV2SEnv

    settings = VideoSettings.of(settings, options)
    if settings.policy is None:
        raise FailureReplayError("running a script's episode needs the policy (policy=...)")
    stall_seconds = _check_window(settings)
    script_path, out_path = Path(script_path), Path(out_path)
    name = scenario or (script_path.parent.name if script_path.name == "scenario.scenic" else script_path.stem)
    config = {**dict(settings.env_config or {}), **VIDEO_CONFIG}
    frequency = _frequency(config)
    seed, episode_steps = int(episode["seed"]), int(episode["steps"])
    failure, trajectory_hash = episode.get("failure") or None, episode.get("trajectory_hash")
    stall = (failure or {}).get("type") == "stall"
    k = (failure_step(failure, episode_steps, frequency) if failure
         else max(0, min(episode_steps, episode_steps if centre is None else int(centre))))
    span = int(math.ceil(stall_seconds * frequency)) if stall else 0  # an upper bound of the stall's frames
    end = k + span + int(round(settings.after * frequency))
    env = DV2SEnv(scenario=str(script_path), config=config, render_mode="rgb_array")
    result, trace, frames = _checked_run(
        env, settings.policy, _Scene(name, seed, {}), True, max(0, end - episode_steps), trajectory_hash,
        lambda got: (f"the rendered run of {script_path} (seed {seed}) diverged from its episode: trajectory hash "
                     f"{got[:12]} != {str(trajectory_hash)[:12]}"))
    start, stop = _write_window(out_path, frames, trace, k, frequency, stall_seconds if stall else None,
                               settings)
    return FailureVideo(out_path, None, start, stop, k, frequency, result, trace)
