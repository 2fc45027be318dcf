"""Frames of a bird's-eye clip: reading them densely enough, colour conversion, and the check
that they look like a highway-env style render (:class:`NotBirdsEyeError` otherwise)."""

from __future__ import annotations

import os
from typing import Any, Dict, List, Sequence, Tuple

import numpy as np

from scenario_bank.errors import DV2SError
from dv2s_gym.pipeline.video import read_video

__all__ = ["BEV_READ_OPTIONS", "MIN_RESAMPLE_FPS", "NotBirdsEyeError"]


BEV_READ_OPTIONS = {"fps": 5.0, "max_frames": 100, "max_pixels": 448 * 448}
""":func:`~dv2s_gym.pipeline.video.read_video` arguments that suit this backend."""


MIN_RESAMPLE_FPS = 4.0


class NotBirdsEyeError(DV2SError, ValueError):
    """The video is not a bird's-eye render in highway-env's style."""


def _hsv(frame: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.cvtColor(frame, cv2.COLOR_RGB2HSV)


def _mask(hsv: np.ndarray, lo: Tuple[int, int, int], hi: Tuple[int, int, int]) -> np.ndarray:
    import cv2

    return cv2.inRange(hsv, lo, hi)


def _check_birds_eye(frames: Sequence[np.ndarray], path: str) -> Dict[str, float]:
    """Background statistics of a few frames; NotBirdsEyeError when they are not a BEV render."""
    picks = [frames[i] for i in sorted(set(np.linspace(0, len(frames) - 1, min(6, len(frames))).astype(int)))]
    shares, spreads, ego_frames = [], [], 0
    for f in picks:
        hsv = _hsv(f)
        grey = _mask(hsv, (0, 0, 71), (179, 29, 134)) > 0
        share = float(grey.mean())
        shares.append(share)
        spreads.append(float(hsv[..., 2][grey].std()) if share > 0 else 99.0)
        if int(np.count_nonzero(_mask(hsv, (37, 70, 90), (78, 255, 255)))) >= 12:
            ego_frames += 1
    stats = {"grey_share": round(float(np.median(shares)), 3), "grey_spread": round(float(np.median(spreads)), 2),
             "ego_frames": round(ego_frames / len(picks), 2)}
    reasons = []
    if stats["grey_share"] < 0.45:
        reasons.append(f"only {stats['grey_share']:.0%} of the pixels are the flat grey canvas (expected most)")
    elif stats["grey_spread"] > 6.0:
        reasons.append(f"its grey areas are textured (brightness spread {stats['grey_spread']:.1f}), as in a photo")
    if stats["ego_frames"] < 0.5:
        reasons.append("no green ego vehicle is visible in most frames")
    if reasons:
        raise NotBirdsEyeError(
            f"{path or 'the video'} does not look like a bird's-eye render in highway-env's style "
            f"({'; '.join(reasons)}). The 'bev' analyzer only reads such renders (grey canvas, white lane "
            "lines, green ego vehicle at a fixed spot); describe dashcam or other real driving videos with the "
            "VLM backend instead (--dra openai)."
        )
    return stats


def _frames_and_times(clip) -> Tuple[List[np.ndarray], np.ndarray, str, Dict[str, Any]]:
    frames = list(getattr(clip, "frames", None) or [])
    path = str(getattr(clip, "path", "") or "")
    times = getattr(clip, "times", None)
    info: Dict[str, Any] = {"input_frames": len(frames)}
    if times is None or len(times) != len(frames):
        times = [i / 5.0 for i in range(len(frames))]
    times = np.asarray(times, float)
    rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
    source_fps = float(getattr(clip, "source_fps", 0.0) or 0.0)
    if rate < MIN_RESAMPLE_FPS and source_fps > rate + 0.5 and path and os.path.isfile(path):
        options = dict(BEV_READ_OPTIONS)
        if frames:
            h, w = frames[0].shape[:2]
            options["max_pixels"] = max(w * h, 1)
        dense = read_video(path, **options)
        if len(dense.frames) > len(frames):
            info["resampled_from"] = f"{len(frames)} frames at {rate:.2f}/s"
            frames, times = list(dense.frames), np.asarray(dense.times, float)
    info["frames"] = len(frames)
    return frames, times, path, info
