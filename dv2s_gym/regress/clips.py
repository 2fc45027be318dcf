"""Short video clips of recorded episodes, rendered by replaying their traces.

A regression report shows its newly failing episodes as clips: the trace an
episode left behind is replayed (every actor state checked against it) in an env
that renders off-screen, and the last few seconds before the end are written as a
small VP8 ``.webm`` that browsers play.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from envs.errors import DV2SError
from envs.trace import EpisodeTrace
from envs.trace_bounds import check_file_config, TraceConfigError
from envs.recording import VideoWriter
from dv2s_gym.regress.records import BankInfo, RegressReport
from dv2s_gym.regress.replay import bank_for_scenario
from scenario_bank.records import RegressEpisode, recorded
from policies.evaluation import make_eval_env, run_episode
from policies.registry import load_policy, PolicyError, spec_from_file

__all__ = ["ClipError", "render_episode_video", "render_policy_video", "clip_window", "DEFAULT_CLIP_CONFIG"]

DEFAULT_CLIP_CONFIG: Dict[str, Any] = {
    "seconds": 7.0,
    "size": 360,
    "zoom": 1.25,
}
"""``seconds``: length of the clip, counted back from the episode's end; ``size``: width and height [px];
``zoom``: magnification over the episode's own view (1 = the same ground, in fewer pixels)."""


class ClipError(DV2SError, ValueError):
    """A clip that cannot be rendered (missing or unreadable trace, nothing to render)."""


def render_episode_video(trace_path: Union[str, os.PathLike], out_path: Union[str, os.PathLike], *,
                         seconds: float = DEFAULT_CLIP_CONFIG["seconds"],
                         size: int = DEFAULT_CLIP_CONFIG["size"],
                         zoom: float = DEFAULT_CLIP_CONFIG["zoom"], end_step: Optional[int] = None) -> Path:
    """Replay the trace at ``trace_path`` and write its last ``seconds`` to ``out_path`` (``.webm``); with
    ``end_step``, the ``seconds`` up to that step instead (:func:`clip_window`: the same window of time in two
    episodes of one scene).

    The view covers the ground of the episode's own rendering settings divided by
    ``zoom``, in ``size`` x ``size`` pixels; frames come at the policy frequency. The
    replay checks every actor state against the trace, so a clip shows exactly the
    recorded episode (a diverging replay raises
    :class:`~envs.trace.TraceMismatchError`). Returns ``out_path``.
    """
    from envs.replay import replay_trace
    trace_path = Path(trace_path)
    if not trace_path.is_file():
        raise ClipError(f"episode trace {trace_path} does not exist; run the regression again to record traces")
    if seconds <= 0 or size < 16 or zoom <= 0:
        raise ClipError(f"a clip needs seconds > 0, size >= 16 px and zoom > 0, "
                        f"not seconds={seconds}, size={size}, zoom={zoom}")
    try:
        trace = EpisodeTrace.load(trace_path)
    except ValueError as error:
        raise ClipError(str(error)) from None
    config = dict(trace.config)
    frequency = float(config.get("policy_frequency") or 5)
    width = float(config.get("screen_width") or 600)
    config.update(
        screen_width=int(size),
        screen_height=int(size),
        scaling=float(config.get("scaling") or 5.5) * zoom * size / width,
        offscreen_rendering=True,
    )
    frames: List[np.ndarray] = []
    env, _ = replay_trace(dataclasses.replace(trace, config=config), render_mode="rgb_array", frames=frames)
    env.close()
    return _write_window(frames, seconds, frequency, out_path, f"episode trace {trace_path}", end_step)


def render_policy_video(report: RegressReport, result: RegressEpisode, role: str,
                        out_path: Union[str, os.PathLike], *,
                        seconds: float = DEFAULT_CLIP_CONFIG["seconds"], size: int = DEFAULT_CLIP_CONFIG["size"],
                        zoom: float = DEFAULT_CLIP_CONFIG["zoom"], end_step: Optional[int] = None) -> Path:
    """Re-run ``role``'s policy of a regression report on ``result``'s scene and write its last ``seconds``
    (with ``end_step``: the ``seconds`` up to that step, as :func:`render_episode_video`).

    For an episode that kept no trace (one that did not fail): the policy spec, scenario, seed and env
    config of the report, rendered off-screen like :func:`render_episode_video`. ``result`` is the episode's
    result in the report (a :class:`~scenario_bank.records.RegressEpisode`). The re-run must
    reproduce the report's trajectory hash, so the clip shows the very episode the report counted.
    """
    policy_info = report.candidate if role == "candidate" else report.baseline
    spec = policy_info.spec if policy_info is not None else None
    if not spec:
        raise ClipError(f"the report names no {role} policy to re-run")
    if policy_info.report:  # the spec came from another report file, not the command line

        try:
            spec_from_file(spec, f"the baseline report {policy_info.report}", "--baseline SPEC (instead of --baseline-report)")
        except PolicyError as error:
            raise ClipError(str(error)) from None
    if seconds <= 0 or size < 16 or zoom <= 0:
        raise ClipError(f"a clip needs seconds > 0, size >= 16 px and zoom > 0, "
                        f"not seconds={seconds}, size={size}, zoom={zoom}")
    scenario, seed = result.scenario, int(result.seed)
    try:
        config = check_file_config(report.settings.env_config if report.settings is not None else None, "the report")
    except TraceConfigError as error:
        raise ClipError(str(error)) from None
    env = make_eval_env(None, config=config, bank_dir=bank_for_scenario(report.bank if recorded(report.bank) else BankInfo(), scenario),
                        render_mode="rgb_array")
    frames: List[np.ndarray] = []
    try:
        own = env.unwrapped.config
        own.update(scaling=float(own.get("scaling") or 5.5) * zoom * size / float(own.get("screen_width") or 600),
                   screen_width=int(size), screen_height=int(size), offscreen_rendering=True)
        policy = load_policy(spec)
        policy.bind([env])
        rerun, _ = run_episode(env, policy, scenario, seed, frames=frames)
        frequency = float(own.get("policy_frequency") or 5)
    finally:
        env.close()
    expected = result.trajectory_hash
    if expected and rerun.trajectory_hash != expected:
        raise ClipError(f"the {role}'s run of {scenario}/{seed} did not reproduce (trajectory hash "
                        f"{rerun.trajectory_hash[:12]}, the report has {str(expected)[:12]}); the policy or the "
                        "simulator changed since the report was made")
    return _write_window(frames, seconds, frequency, out_path, f"the {role}'s run of {scenario}/{seed}", end_step)


def clip_window(end_step: int, seconds: float, frequency: float) -> Tuple[int, int]:
    """``(first, last)`` step of a clip of ``seconds`` (as many frames as :func:`render_episode_video`'s last
    ``seconds``) ending at step ``end_step``, both included; frame ``i`` shows the scene after ``i`` steps, at
    ``i / frequency`` s: the same window in any episode of the scene."""
    last = max(0, int(end_step))
    return max(0, last - max(1, int(round(seconds * frequency))) + 1), last


def _write_window(frames: List[np.ndarray], seconds: float, frequency: float,
                  out_path: Union[str, os.PathLike], what: str, end_step: Optional[int] = None) -> Path:
    """Write the last ``seconds`` of ``frames`` (with ``end_step``: the :func:`clip_window` up to that step) as a
    video; :class:`ClipError` naming ``what`` if there are none."""
    if end_step is None:
        frames = frames[-max(1, int(round(seconds * frequency))):]
    else:
        first, last = clip_window(end_step, seconds, frequency)
        frames = frames[first:last + 1]
    if not frames:
        raise ClipError(f"{what} rendered no frames")
    with VideoWriter(out_path, fps=frequency) as video:
        for frame in frames:
            video.write(frame)
    return Path(out_path)
