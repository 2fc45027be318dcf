"""Record episodes to video files that browsers play."""

from __future__ import annotations

import os
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from scenario_bank.atomic import atomic_path
from scenario_bank.errors import DV2SError, SettingError

__all__ = ["VideoWriter", "VideoFormatError", "VideoEncoderError", "record_episode", "write_frames"]

class VideoFormatError(DV2SError, ValueError):
    """A video path whose extension no codec here writes; the message lists the ones that work."""


class VideoEncoderError(DV2SError, RuntimeError):
    """OpenCV on this machine cannot encode the video format asked for; the message names one it can."""


_CODECS = {".webm": "VP80", ".mp4": "avc1", ".avi": "MJPG", ".mkv": "VP80"}


@contextmanager
def _quiet_stderr():
    """Silence the process's stderr file descriptor (C libraries write there directly)."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class VideoWriter:
    """Write RGB frames to a video file (VP8 ``.webm`` by default; written atomically).

    ``.mp4`` is tried with H.264 and falls back to ``mp4v`` when OpenCV has no
    H.264 encoder (mp4v plays in desktop players, not all browsers).
    """

    def __init__(self, path: Union[str, os.PathLike], fps: float = 15.0) -> None:
        self.path = Path(path)
        self.fps = float(fps)
        self._writer = None
        self._target: Optional[ExitStack] = None  # the atomic write of the file, open while frames come
        self.frames = 0

    def _open(self, width: int, height: int):
        import cv2

        suffix = self.path.suffix.lower()
        if suffix not in _CODECS:
            raise VideoFormatError(f"unsupported video extension {suffix!r}; use one of {sorted(_CODECS)}")
        self._target = ExitStack()
        tmp = self._target.enter_context(atomic_path(self.path, keep_suffix=True))
        for fourcc in ([_CODECS[suffix], "mp4v"] if suffix == ".mp4" else [_CODECS[suffix]]):
            with _quiet_stderr():  # FFmpeg prints a harmless "tag not supported" notice for VP80
                writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), self.fps, (width, height))
            if writer.isOpened():
                return writer
        self._abandon()
        raise VideoEncoderError(f"OpenCV cannot encode {suffix} here; write .webm (VP8) instead")

    def write(self, frame: np.ndarray) -> None:
        """Append one ``HxWx3`` uint8 RGB frame."""
        import cv2

        frame = np.ascontiguousarray(frame[..., :3], dtype=np.uint8)
        if self._writer is None:
            self._writer = self._open(frame.shape[1], frame.shape[0])
        self._writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> Path:
        """Finish the file and move it into place."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
            target, self._target = self._target, None
            target.close()  # renames the finished file into place
        return self.path

    def _abandon(self) -> None:
        """Drop the unfinished file; the target path is left as it was."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._target is not None:
            target, self._target = self._target, None
            target.__exit__(RuntimeError, RuntimeError("video abandoned"), None)

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self._abandon()


def record_episode(
    env,
    path: Union[str, os.PathLike],
    policy: Optional[Callable[[np.ndarray, dict], object]] = None,
    *,
    seed: Optional[int] = None,
    max_steps: Optional[int] = None,
) -> dict:
    """Run one episode of an ``rgb_array`` env and write it to ``path``.

    ``policy(obs, info) -> action``; default samples the action space, seeded with ``seed`` so that a
    seeded random episode is the same every time. Frames are
    captured at the simulation frequency for smooth video. Returns a summary
    (steps, return, termination, info of the last step, frames written).
    """
    base = env.unwrapped
    if getattr(base, "render_mode", None) != "rgb_array":
        raise SettingError("record_episode needs an env made with render_mode='rgb_array'; make the env with that "
                           "render mode")
    fps = base.config.get("policy_frequency", 5)
    obs, info = env.reset(seed=seed)
    if policy is None and seed is not None:
        env.action_space.seed(seed)  # the reset seeds the scene, not the space the random actions come from
    total, steps, terminated, truncated = 0.0, 0, False, False
    with VideoWriter(path, fps=fps) as video:
        video.write(env.render())
        while not (terminated or truncated):
            action = policy(obs, info) if policy else env.action_space.sample()
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            steps += 1
            video.write(env.render())
            if max_steps is not None and steps >= max_steps:
                break
    return {"steps": steps, "return": total, "terminated": terminated, "truncated": truncated,
            "info": info, "frames": video.frames, "path": str(path)}


def write_frames(path: Union[str, os.PathLike], frames, fps: float) -> None:
    """Write rendered frames (``rgb_array`` images) to the video ``path`` at ``fps`` frames per second."""
    with VideoWriter(path, fps=fps) as video:
        for frame in frames:
            video.write(frame)
