"""A mined failure as a bird's-eye video of the seconds before and through it, plus its trace.

The failure is re-run from its episode record (scenario, seed, sampled parameters) with the
same deterministic policy in an env that renders off-screen; the re-run must reproduce the
record's trajectory hash, or :class:`FailureReplayError` says the replay diverged. A saved
trace (:class:`~envs.trace.EpisodeTrace` or its file) is replayed with its own actions instead
(:func:`envs.replay.replay_trace`, every actor state checked). The frames from ``before``
seconds before the failure through ``after`` seconds after it are written as a VP8 ``.webm``
(:class:`envs.recording.VideoWriter`) at the policy frequency, in the style the ``bev`` Driving
Record Analyzer reads (the camera follows the ego, north up, 5.5 px/m).

The frame covers the actor the failure involves (:func:`dv2s_gym.mining.conversion.interaction.key_actor`, the actor the
conversion's description and judge name: the failure's partner, or for a stall the one ahead in the ego's
lane): a 480 x 480 px view holds about 44 m around the ego, so when that actor is farther off in the clip's frames the view looks ahead (:func:`clip_camera`): at the same scale, the ego
sits off-centre at one fixed spot of the frame for the whole clip, so that the actor is inside with
:data:`ACTOR_MARGIN` m to spare; when the 480 px are not enough the frame grows that way (up to
:data:`MAX_SCREEN` px) and narrows across (to :data:`MIN_SIDE` of it at least), keeping about the plain view's
pixel count: the analyzer reads frames under a pixel budget, measures the scale from the vehicles' size and finds
the ego at its fixed spot.

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

from dv2s_gym.mining.conversion.interaction import key_actor
from dv2s_gym.mining.monitors import STALL_SPEED, MonitorSettings
from envs.errors import DV2SError
from envs.recording import VideoWriter
from envs.safety_metrics import path_is_free
from envs.trace import EpisodeTrace, TraceMismatchError
from policies.evaluation import run_episode, make_eval_env
from policies.registry import load_policy
from scenario_bank.failure_types import is_standstill
from scenario_bank.records import EpisodeRecord, Failure, RecordError

__all__ = ["FailureReplayError", "FailureVideo", "VIDEO_CONFIG", "VideoSettings", "clip_camera", "failure_step",
           "record_failure_video", "rerun_failure", "stall_end", "write_failure_video", "write_script_episode_video"]

VIDEO_CONFIG: Dict[str, Any] = {"screen_width": 480, "screen_height": 480, "scaling": 5.5,
                                "offscreen_rendering": True, "show_trajectories": False}
"""Rendering settings of failure videos (those of the shipped evaluation clips the ``bev`` DRA was built on).
They change only the pixels, never the trajectory."""

ACTOR_MARGIN = 8.0
"""Metres kept between the filmed actor's centre and the frame's edge (a car's length and more)."""
BEHIND = 12.0
"""Metres on the ego's other side (and around it) a look-ahead view keeps at least."""
MIN_SIDE = 0.6
"""The share of the plain view's extent a grown view keeps across the way it grew (at least)."""
MAX_SCREEN = 1280
"""The largest side (px) a look-ahead view grows to (about 230 m at 5.5 px/m)."""

PathLike = Union[str, os.PathLike]


def _span(offsets: List[float], default: float, limit: float) -> Tuple[float, float]:
    """``(low, size)`` in metres of one axis of the view holding 0 (the ego, with :data:`BEHIND` m around it) and
    every offset (with :data:`ACTOR_MARGIN` m to spare): the plain view's ``default`` metres, centred on the ego
    when that holds them, else shifted only as far as needed (as much of the plain view kept as fits); wider
    than ``default`` only when it must be, up to ``limit`` (the farther side first)."""
    low = min([-BEHIND] + [o - ACTOR_MARGIN for o in offsets])
    high = max([BEHIND] + [o + ACTOR_MARGIN for o in offsets])
    if high - low <= default:
        if high > default / 2:
            return high - default, default
        return min(low, -default / 2), default
    if high - low <= limit:
        return low, high - low
    return (-BEHIND, limit) if high >= -low else (BEHIND - limit, limit)


def _narrowed(offsets: List[float], default: float, size: float) -> Tuple[float, float]:
    """``(size, low)`` of an axis narrowed from ``default`` to ``size`` metres (no less than what it must hold:
    the ego and the offsets with their margins), centred on what it must hold."""
    low = min([-BEHIND] + [o - ACTOR_MARGIN for o in offsets])
    high = max([BEHIND] + [o + ACTOR_MARGIN for o in offsets])
    size = min(default, max(size, high - low))
    middle = 0.0 if -size / 2 <= low and high <= size / 2 else (low + high) / 2
    return size, middle - size / 2


def clip_camera(trace, actor: Optional[str], first: int, last: int,
                base: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """The rendering settings (``screen_width``, ``screen_height``, ``centering_position``) of a view that holds
    ``actor`` in frames ``first`` to ``last`` of ``trace`` (those it has; 0 = the reset) at ``base``'s scale
    (default :data:`VIDEO_CONFIG`); ``{}`` (the plain ego-centred view) when there is no such actor or the plain
    view already holds it. The ego keeps one spot of the frame in the whole clip."""
    base = {**VIDEO_CONFIG, **dict(base or {})}
    states = list(getattr(trace, "states", None) or [])[max(0, first): max(0, last) + 1]
    offsets = [(s[actor][0] - s["ego"][0], s[actor][1] - s["ego"][1])
               for s in states if actor and actor in s and "ego" in s]
    if not offsets:
        return {}
    scaling = float(base["scaling"])
    width_m, height_m = base["screen_width"] / scaling, base["screen_height"] / scaling
    x0, w = _span([o[0] for o in offsets], width_m, MAX_SCREEN / scaling)
    y0, h = _span([o[1] for o in offsets], height_m, MAX_SCREEN / scaling)
    if (x0, w, y0, h) == (-width_m / 2, width_m, -height_m / 2, height_m):
        return {}
    # a view grown along one axis gives up some of the other one's plain extent (down to MIN_SIDE of it, never
    # what it must hold): the describing reads frames under a pixel budget, so a larger frame draws smaller cars
    area = width_m * height_m
    if w > width_m and h <= height_m:
        h, y0 = _narrowed([o[1] for o in offsets], height_m, max(MIN_SIDE * height_m, area / w))
    elif h > height_m and w <= width_m:
        w, x0 = _narrowed([o[0] for o in offsets], width_m, max(MIN_SIDE * width_m, area / h))
    width, height = 2 * int(math.ceil(w * scaling / 2)), 2 * int(math.ceil(h * scaling / 2))  # even: VP8's frames
    return {"screen_width": width, "screen_height": height,
            "centering_position": [round(-x0 * scaling / width, 6), round(-y0 * scaling / height, 6)]}


class FailureReplayError(DV2SError, ValueError):
    """A failure that cannot be re-run: a malformed record, or a replay that diverged from it."""


def _frequency(config: Mapping[str, Any]) -> float:
    return float(config.get("policy_frequency") or 5)


def failure_step(failure: Optional[Failure], steps: int, frequency: float) -> int:
    """The frame index (0 = the reset) showing the failure: the failure's ``step`` when given, else the
    frame nearest its ``time`` (as the miner's monitors count steps); the last frame when neither is
    known. Clipped to ``[0, steps]``."""
    if failure is not None and failure.step is not None:
        k = int(failure.step)
    elif failure is not None and failure.time is not None:
        k = int(round(float(failure.time) * frequency))
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


def _trace_failure(trace) -> Optional[Failure]:
    """The first failure event of a trace (a collision involving the ego, with the other actor, or leaving the
    road)."""
    event = trace.first_failure_event()
    if event is None:
        return None
    other = trace.other_actor(event) if event["kind"] == "collision" else None
    return Failure(str(event["kind"]), float(event["time"]), with_=other)


def _episode_record(record: Union[EpisodeRecord, Mapping[str, Any]]) -> EpisodeRecord:
    """The episode record ``record`` (a record, or its JSON object as ``episodes.jsonl`` holds it), checked to have
    what a re-run needs: the scenario, the seed and the result's trajectory hash."""
    if isinstance(record, EpisodeRecord):
        data = record.to_dict()
    elif isinstance(record, Mapping):
        data = record
    else:
        raise FailureReplayError(f"a failure record must be an episode record of episodes.jsonl, not "
                                 f"{type(record).__name__}")
    missing = [key for key in ("scenario", "seed") if data.get(key) is None]
    if not (data.get("result") or {}).get("trajectory_hash"):
        missing.append("result.trajectory_hash")
    if missing:
        raise FailureReplayError(f"the failure record lacks {', '.join(missing)}; pass an episode record of "
                                 "episodes.jsonl (or a saved episode trace)")
    try:
        return EpisodeRecord.from_dict(record)
    except RecordError as error:
        raise FailureReplayError(f"the failure record is not an episode record of episodes.jsonl: {error}") from None


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


def rerun_failure(record: EpisodeRecord, *, policy: Any,
                  bank_dir: Optional[PathLike] = None, env_config: Optional[Mapping[str, Any]] = None, render: bool = False,
                  extra_steps: int = 0, camera: Optional[Mapping[str, Any]] = None) -> Tuple[Any, Any, List[np.ndarray]]:
    """Re-run an episode record with ``policy`` (a spec or a :class:`~policies.registry.Policy`).

    Returns ``(EpisodeResult, EpisodeTrace, frames)``; frames (when ``render``) hold the reset and every
    step, then ``extra_steps`` more steps driven past the episode's end, drawn with :data:`VIDEO_CONFIG` and
    ``camera`` (:func:`clip_camera`) on top. Raises :class:`FailureReplayError` when the trajectory hash differs
    from the record's.
    """
    record = _episode_record(record)
    config = dict(env_config or {})
    if render:
        config.update(VIDEO_CONFIG)
        config.update(camera or {})
    env = make_eval_env([record.scenario], config=config, bank_dir=str(bank_dir) if bank_dir else None,
                        render_mode="rgb_array" if render else None)
    expected = record.result.trajectory_hash
    scene = _Scene(record.scenario, int(record.seed), record.params or {})
    return _checked_run(env, policy, scene, render, extra_steps, expected,
                        lambda got: (f"the replay of episode {record.index} ({record.scenario}, seed "
                                     f"{record.seed}) diverged: trajectory hash {got[:12]} != recorded "
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


def _replay_trace_frames(trace, camera: Optional[Mapping[str, Any]] = None) -> List[np.ndarray]:
    from envs.replay import replay_trace

    config = {**trace.config, **VIDEO_CONFIG, **dict(camera or {})}
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
    ``env_config``, the seconds of video ``before`` and ``after`` the failure, and the failure ``monitor``'s settings,
    whose ``stall_seconds`` is the longest stall a clip covers (``None``: the monitors' defaults)."""

    policy: Any = None
    bank_dir: Optional[PathLike] = None
    env_config: Optional[Mapping[str, Any]] = None
    before: float = 4.0
    after: float = 1.0
    monitor: Optional[MonitorSettings] = None

    @classmethod
    def of(cls, settings: Optional["VideoSettings"], options: Mapping[str, Any]) -> "VideoSettings":
        """``settings`` (default: the defaults) with ``options`` (its fields by name) on top."""
        return dataclasses.replace(settings or cls(), **dict(options))


def record_failure_video(record_or_trace: Union[EpisodeRecord, Mapping[str, Any], Any, PathLike], out_path: PathLike,
                         settings: Optional[VideoSettings] = None, *, trace_path: Optional[PathLike] = None,
                         **options: Any) -> Path:
    """Write the bird's-eye video of a failure (``.webm``) and its trace; returns the video's path.

    ``record_or_trace`` is an episode record of the miner (re-run with the settings' ``policy``, which must be the
    deterministic policy that failed, and checked against the record's trajectory hash) or an
    :class:`~envs.trace.EpisodeTrace` or trace file (replayed with its recorded actions; ``policy`` is
    not needed, and the clip cannot run past the trace's end). ``settings`` (:class:`VideoSettings`), or its
    fields given one by one as keywords (``policy=``, ``before=``...). The clip holds the frames from
    ``before`` seconds before the failure (the record's ``failure``; for a trace, its first ego
    collision or off-road event) through ``after`` seconds after it, at the policy frequency:
    ``round(before * f) + round(after * f) + 1`` frames unless the episode started less than
    ``before`` seconds before the failure. A record's ``stall`` covers the stall: the window runs from
    ``before`` seconds before its start through its last standing frame (:func:`stall_end`, at most
    the monitor's ``stall_seconds`` after the start) plus ``after``
    seconds. The trace is saved to ``trace_path`` (default ``trace.json.gz`` beside the video).
    """
    return write_failure_video(record_or_trace, out_path, settings, trace_path=trace_path, **options).path


def _window(trace, k: int, frequency: float, stall: bool, settings: VideoSettings,
            frames: int) -> Tuple[int, int]:
    """The first and last frame of the clip around frame ``k`` (:func:`_write_window`) of ``frames`` frames."""
    start = max(0, k - int(round(settings.before * frequency)))
    last = stall_end(trace, k, _stall_span(settings, frequency)) if stall else k
    return start, min(frames - 1, last + int(round(settings.after * frequency)))


def _stall_span(settings: VideoSettings, frequency: float) -> int:
    """The frames of the longest stall a clip covers: the monitor's ``stall_seconds``."""
    return int(math.ceil(MonitorSettings.of(settings.monitor).stall_seconds * frequency))


def _camera(trace, failure: Optional[Failure], k: int, frequency: float, stall: bool,
            settings: VideoSettings, frames: int) -> Dict[str, Any]:
    """The look-ahead view (:func:`clip_camera`) that holds the actor ``failure`` involves in the clip's frames
    (those up to the failure's frame, or through a ``stall``)."""
    start, end = _window(trace, k, frequency, stall, settings, frames)
    return clip_camera(trace, key_actor(trace, failure) if failure is not None else None, start, end)


def _write_window(out_path: Path, frames: List[np.ndarray], trace, k: int, frequency: float,
                  stall: bool, settings: VideoSettings) -> Tuple[int, int]:
    """Write the frames (``frequency`` per second) from ``before`` seconds before frame ``k`` to ``after`` seconds
    after it (after the stall's end for a ``stall``) to ``out_path``. Returns the first and last frame written."""
    start, end = _window(trace, k, frequency, stall, settings, len(frames))
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with VideoWriter(out_path, fps=frequency) as video:
        for frame in frames[start:end + 1]:
            video.write(frame)
    return start, end


def write_failure_video(record_or_trace: Union[EpisodeRecord, Mapping[str, Any], Any, PathLike], out_path: PathLike,
                        settings: Optional[VideoSettings] = None, *, trace_path: Optional[PathLike] = None,
                        **options: Any) -> FailureVideo:
    """:func:`record_failure_video`, returning a :class:`FailureVideo` (window, result, trace)."""
    settings = VideoSettings.of(settings, options)
    _check_window(settings)
    out_path = Path(out_path)
    trace_path = Path(trace_path) if trace_path is not None else out_path.parent / "trace.json.gz"
    if isinstance(record_or_trace, (EpisodeRecord, Mapping)):
        clip = _record_clip(_episode_record(record_or_trace), settings)
    else:
        clip = _trace_clip(record_or_trace, settings)
    frames, result, trace, frequency, k, stall = clip
    start, end = _write_window(out_path, frames, trace, k, frequency, stall, settings)
    trace.save(trace_path)
    return FailureVideo(out_path, trace_path, start, end, k, frequency, result, trace)


def _check_window(settings: VideoSettings) -> None:
    """Check the settings' ``before``, ``after`` and the monitor's ``stall_seconds``."""
    if settings.before < 0 or settings.after < 0:
        raise FailureReplayError(f"before and after must be >= 0 seconds, not {settings.before} and {settings.after}")
    stall_seconds = MonitorSettings.of(settings.monitor).stall_seconds
    if not stall_seconds > 0:
        raise FailureReplayError(f"stall_seconds must be > 0, not {stall_seconds}")


def _record_clip(record: EpisodeRecord, settings: VideoSettings) -> tuple:
    """``(frames, result, trace, frequency, failure frame, stall)`` of an episode record, re-run far enough past
    its end to show ``after`` seconds (and a stall's standing frames) past the failure."""
    if settings.policy is None:
        raise FailureReplayError("re-running a failure record needs the policy that failed (policy=...)")
    frequency = _frequency({**VIDEO_CONFIG, **dict(settings.env_config or {})})
    steps = int(record.result.steps or 0) if record.result is not None else 0
    k = failure_step(record.failure, steps, frequency)
    stall = record.failure is not None and is_standstill(record.failure.type)
    span = _stall_span(settings, frequency) if stall else 0  # an upper bound of the stall's frames
    end = k + span + int(round(settings.after * frequency))
    camera: Dict[str, Any] = {}
    for attempt in range(2):  # the plain view, then (when the actor is out of it) the look-ahead view
        result, trace, frames = rerun_failure(record, policy=settings.policy, bank_dir=settings.bank_dir,
                                              env_config=settings.env_config, render=True,
                                              extra_steps=max(0, end - steps), camera=camera)
        frequency = _frequency(trace.config)
        k = failure_step(record.failure, len(trace.actions), frequency)
        wanted = _camera(trace, record.failure, k, frequency, stall, settings, len(frames))
        if wanted == camera or attempt:  # the actor is in view (the second run's trace is the first's: same hash)
            break
        camera = wanted
    return frames, result, trace, frequency, k, stall


def _trace_clip(source: Any, settings: VideoSettings) -> tuple:
    """``(frames, None, trace, frequency, failure frame, False)`` of a saved trace (or its file), replayed with its
    recorded actions."""
    trace = source if isinstance(source, EpisodeTrace) else None
    if trace is None:
        try:
            trace = EpisodeTrace.load(source)
        except (OSError, ValueError) as error:
            raise FailureReplayError(f"cannot read the failure trace {source}: {error}") from None
    frequency = _frequency(trace.config)
    failure = _trace_failure(trace)
    k = failure_step(failure, len(trace.actions), frequency)
    camera = _camera(trace, failure, k, frequency, False, settings, len(trace.states))
    frames = _replay_trace_frames(trace, camera)
    return frames, None, trace, frequency, k, False


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
    _check_window(settings)
    script_path, out_path = Path(script_path), Path(out_path)
    name = scenario or (script_path.parent.name if script_path.name == "scenario.scenic" else script_path.stem)
    config = {**dict(settings.env_config or {}), **VIDEO_CONFIG}
    frequency = _frequency(config)
    seed, episode_steps = int(episode["seed"]), int(episode["steps"])
    failure, trajectory_hash = Failure.of(episode.get("failure")), episode.get("trajectory_hash")
    stall = failure is not None and is_standstill(failure.type)
    k = (failure_step(failure, episode_steps, frequency) if failure is not None
         else max(0, min(episode_steps, episode_steps if centre is None else int(centre))))
    span = _stall_span(settings, frequency) if stall else 0  # an upper bound of the stall's frames
    end = k + span + int(round(settings.after * frequency))
    camera: Dict[str, Any] = {}
    for attempt in range(2):  # the plain view, then (when the actor is out of it) the look-ahead view
        env = DV2SEnv(scenario=str(script_path), config={**config, **camera}, render_mode="rgb_array")
        result, trace, frames = _checked_run(
            env, settings.policy, _Scene(name, seed, {}), True, max(0, end - episode_steps), trajectory_hash,
            lambda got: (f"the rendered run of {script_path} (seed {seed}) diverged from its episode: trajectory "
                         f"hash {got[:12]} != {str(trajectory_hash)[:12]}"))
        wanted = _camera(trace, failure, k, frequency, stall, settings, len(frames))
        if wanted == camera or attempt:
            break
        camera = wanted
    start, stop = _write_window(out_path, frames, trace, k, frequency, stall, settings)
    return FailureVideo(out_path, None, start, stop, k, frequency, result, trace)
