"""Driving Record Analyzer on an OpenAI-compatible vision-language model.

The clip's frames go to the VLM as JPEG data URLs, in temporal order, after the
DRA prompt of :mod:`dv2s_gym.pipeline.prompts`, in one user message::

    client = ChatClient.from_config(None, kind="vlm")
    text, provenance = describe_with_vlm(frames, client, camera="chase",
                                         question="Why did the ego vehicle brake hard?")

VLMs accept a limited number of images per request, so a longer clip is
subsampled evenly (first and last frame kept) down to ``max_frames``, and
frames are scaled down so their longer side is at most ``max_side`` pixels.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, replace
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from dv2s_gym.pipeline.errors import FrameEncodeError, MalformedResponseError
from dv2s_gym.pipeline.prompts import dra_prompt, normalize_camera, prompt_hash
from dv2s_gym.pipeline.video import VideoError
from scenario_bank.errors import SettingError

__all__ = ["VLMSettings", "describe_with_vlm", "frame_to_data_url", "select_frames"]


def _as_rgb_uint8(frame: Any, index: int) -> np.ndarray:
    array = np.asarray(frame)
    if array.ndim == 2:
        array = np.repeat(array[:, :, None], 3, axis=2)
    if array.ndim != 3 or array.shape[2] not in (3, 4) or array.shape[0] == 0 or array.shape[1] == 0:
        raise VideoError(f"frame {index} must be an RGB image of shape (H, W, 3), got shape {array.shape}")
    array = array[:, :, :3]
    if array.dtype != np.uint8:
        if np.issubdtype(array.dtype, np.floating) and array.size and float(np.nanmax(array)) <= 1.0:
            array = array * 255.0
        array = np.clip(np.nan_to_num(array), 0, 255).astype(np.uint8)
    return array


def frame_to_data_url(frame: Any, quality: int = 85, max_side: Optional[int] = 768) -> str:
    """An RGB frame (H, W, 3) as a ``data:image/jpeg;base64,...`` URL, scaled to ``max_side``."""
    import cv2

    rgb = _as_rgb_uint8(frame, 0)
    height, width = rgb.shape[:2]
    if max_side and max(height, width) > max_side:
        scale = max_side / max(height, width)
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    ok, buffer = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV fails only on broken builds
        raise FrameEncodeError("OpenCV could not encode a frame as JPEG")
    return "data:image/jpeg;base64," + base64.b64encode(buffer.tobytes()).decode("ascii")


def select_frames(count: int, max_frames: int) -> List[int]:
    """Indices of at most ``max_frames`` of ``count`` frames, evenly spread, in order."""
    if count <= max_frames:
        return list(range(count))
    if max_frames == 1:
        return [count // 2]
    return sorted({int(round(i)) for i in np.linspace(0, count - 1, max_frames)})


@dataclass(frozen=True)
class VLMSettings:
    """What :func:`describe_with_vlm` sends: how many frames, how large, and the reply's limits."""

    max_frames: int = 16
    """Frames sent at most, spread evenly over the clip (:func:`select_frames`)."""
    max_side: Optional[int] = 768
    """Longest side of a sent frame [px] (``None``: as recorded)."""
    jpeg_quality: int = 85
    max_tokens: int = 400
    temperature: float = 0


def describe_with_vlm(clip_frames: Sequence[Any], client: Any, camera: str = "front", question: Optional[str] = None,
                      *, settings: Optional[VLMSettings] = None, **options: Any) -> Tuple[str, Dict[str, Any]]:
    """Describe a clip with a VLM; returns ``(description, provenance)``.

    Args:
        clip_frames: RGB frames (``(H, W, 3)`` uint8 arrays) in temporal order.
        client: a :class:`~dv2s_gym.pipeline.llm_client.ChatClient` of a vision model.
        camera: ``front``, ``rear``, ``chase`` or ``bev`` (or an alias of
            :data:`~dv2s_gym.pipeline.prompts.CAMERA_ALIASES`).
        question: the video-specific question about the event of interest.
        settings: frames and reply limits (:class:`VLMSettings`; default: its defaults).
        **options: single fields of :class:`VLMSettings` by name, over ``settings`` (``max_frames=8``).

    The provenance holds ``backend`` ("openai"), ``model`` (as the server named
    it), ``prompt_hash``, ``camera``, ``question``, ``frames`` (how many were
    sent), ``endpoint`` and ``usage``.
    """
    settings = replace(settings or VLMSettings(), **options)
    max_frames = settings.max_frames
    frames = list(clip_frames) if clip_frames is not None else []
    if not frames:
        raise VideoError("the clip has no frames to describe")
    if max_frames < 1:
        raise SettingError("max_frames must be at least 1")
    camera_key = normalize_camera(camera)
    prompt = dra_prompt(camera_key, question)
    chosen = select_frames(len(frames), max_frames)
    content: List[Dict[str, Any]] = [{"type": "text", "text": prompt}]
    for index in chosen:
        _as_rgb_uint8(frames[index], index)  # names the bad frame before encoding
        url = frame_to_data_url(frames[index], quality=settings.jpeg_quality, max_side=settings.max_side)
        content.append({"type": "image_url", "image_url": {"url": url}})
    reply = client.chat([{"role": "user", "content": content}], temperature=settings.temperature,
                        max_tokens=settings.max_tokens)
    description = " ".join(reply.text.split())
    if not description:
        raise MalformedResponseError(
            f"the VLM at {client.endpoint} (model {client.model!r}) returned an empty description; check "
            "that the model accepts image input, or raise max_tokens if it stopped early "
            f"(finish_reason={getattr(reply, 'finish_reason', None)!r})",
            endpoint=client.endpoint,
        )
    provenance = {
        "backend": "openai",
        "model": reply.model or client.model,
        "prompt_hash": prompt_hash(prompt),
        "camera": camera_key,
        "question": question,
        "frames": len(chosen),
        "endpoint": client.endpoint,
        "usage": dict(reply.usage or {}),
    }
    return description, provenance
