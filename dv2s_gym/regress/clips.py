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
from typing import Any, Dict, List, Union

import numpy as np

from envs.errors import DV2SError

__all__ = ["ClipError", "render_episode_video", "DEFAULT_CLIP_CONFIG"]

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
                         zoom: float = DEFAULT_CLIP_CONFIG["zoom"]) -> Path:
    """Replay the trace at ``trace_path`` and write its last ``seconds`` to ``out_path`` (``.webm``).

    The view covers the ground of the episode's own rendering settings divided by
    ``zoom``, in ``size`` x ``size`` pixels; frames come at the policy frequency. The
    replay checks every actor state against the trace, so a clip shows exactly the
    recorded episode (a diverging replay raises
    :class:`~envs.trace.TraceMismatchError`). Returns ``out_path``.
    """
    from envs.recording import VideoWriter
    from envs.replay import replay_trace
    from envs.trace import EpisodeTrace

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
    frames = frames[-max(1, int(round(seconds * frequency))):]
    if not frames:
        raise ClipError(f"episode trace {trace_path} rendered no frames")
    with VideoWriter(out_path, fps=frequency) as video:
        for frame in frames:
            video.write(frame)
    return Path(out_path)
