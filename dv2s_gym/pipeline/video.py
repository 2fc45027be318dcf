"""Video input of the pipeline: read a driving video into a small list of RGB frames.

:func:`read_video` opens mp4, mov, webm, avi and mkv files (OpenCV's FFmpeg
backend) and animated gifs (Pillow), samples frames at a fixed rate, caps their
number by spreading them evenly over the whole video, and shrinks them to a
pixel budget. Every way a file can fail to give frames raises a
:class:`VideoError` that names the file, the problem and the fix.
:func:`frames_to_data_urls` turns frames into base64 data URLs for VLM backends.
"""

from __future__ import annotations

import base64
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np
from PIL import Image, ImageSequence, UnidentifiedImageError

from scenario_bank.errors import DV2SError

__all__ = ["VideoClip", "VideoError", "read_video", "frames_to_data_urls", "VIDEO_EXTENSIONS"]

VIDEO_EXTENSIONS = (".mp4", ".m4v", ".mov", ".webm", ".mkv", ".avi", ".gif")
"""Containers :func:`read_video` opens."""

_REENCODE = ("re-encode it to mp4 or webm with ffmpeg, e.g. "
             "`ffmpeg -i '{path}' -c:v libvpx -b:v 2M out.webm` or `ffmpeg -i '{path}' -c:v libx264 out.mp4`")

# first bytes of each container (offset, magic)
_MAGIC = {
    ".mp4": [(4, b"ftyp"), (4, b"moov"), (4, b"mdat"), (4, b"free"), (4, b"wide"), (4, b"skip")],
    ".m4v": [(4, b"ftyp"), (4, b"moov"), (4, b"mdat")],
    ".mov": [(4, b"ftyp"), (4, b"moov"), (4, b"mdat"), (4, b"free"), (4, b"wide"), (4, b"skip")],
    ".webm": [(0, b"\x1a\x45\xdf\xa3")],
    ".mkv": [(0, b"\x1a\x45\xdf\xa3")],
    ".avi": [(0, b"RIFF")],
    ".gif": [(0, b"GIF87a"), (0, b"GIF89a")],
}


_COMMON_CODECS = {"VP8", "VP80", "VP9", "VP90", "MJPG", "MP4V", "FMP4", "XVID", "DIVX", "DX50", "AVC1", "H264", "X264",
                  "MPEG4", "HEVC", "HVC1", "HEV1", "H265"}
"""Codecs OpenCV's FFmpeg backend decodes: a file naming one of these but giving no frame is empty or truncated."""


class VideoError(DV2SError, ValueError):
    """A video file that cannot be read; the message names the file, the problem and the fix."""


@dataclass
class VideoClip:
    """Frames sampled from a video.

    Attributes:
        frames: ``H x W x 3`` uint8 RGB arrays, in temporal order.
        times: timestamp of each frame in the source video [s].
        source_fps: frame rate of the source video [frames/s].
        source_size: ``(width, height)`` of the source frames [px].
        duration: length of the source video [s].
        path: the file the frames come from.
    """

    frames: List[np.ndarray]
    times: List[float]
    source_fps: float
    source_size: Tuple[int, int]
    duration: float
    path: str
    source_frames: int = 0
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def size(self) -> Tuple[int, int]:
        """``(width, height)`` of the returned frames [px]."""
        if not self.frames:
            return (0, 0)
        return (int(self.frames[0].shape[1]), int(self.frames[0].shape[0]))

    @property
    def fps(self) -> float:
        """Mean rate of the returned frames [frames/s] (0 for a single frame)."""
        if len(self.times) < 2 or self.times[-1] <= self.times[0]:
            return 0.0
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])


def _fail(path: Path, problem: str, fix: str) -> VideoError:
    return VideoError(f"cannot read video {str(path)!r}: {problem}. Fix: {fix}.")


def _header_matches(path: Path, suffix: str) -> Optional[bool]:
    magics = _MAGIC.get(suffix)
    if not magics:
        return None
    with open(path, "rb") as handle:
        head = handle.read(16)
    return any(head[offset:offset + len(magic)] == magic for offset, magic in magics)


def _sniff(path: Path, suffix: str) -> Tuple[Optional[str], Optional[int]]:
    """(video codec named in the container header, number of video samples if the header says) or Nones."""
    size = path.stat().st_size
    with open(path, "rb") as handle:
        data = handle.read(1 << 20)
        if size > (2 << 20):
            handle.seek(size - (1 << 20))
            data += handle.read()
    codec: Optional[str] = None
    samples: Optional[int] = None
    if suffix in (".avi",):
        i = data.find(b"vids")
        if i >= 0 and len(data) >= i + 8:
            codec = data[i + 4:i + 8].decode("latin-1")
    elif suffix in (".webm", ".mkv"):
        i = data.find(b"\x86")
        while i >= 0:
            length = data[i + 1] & 0x7F if i + 1 < len(data) and data[i + 1] & 0x80 else 0
            text = data[i + 2:i + 2 + length]
            if length and text.startswith(b"V_"):
                codec = text.decode("latin-1")
                break
            i = data.find(b"\x86", i + 1)
    elif suffix in (".mp4", ".m4v", ".mov"):
        i = data.find(b"stsd")
        if i >= 0 and len(data) >= i + 20:
            codec = data[i + 16:i + 20].decode("latin-1")
        j = data.find(b"stsz")
        if j >= 0 and len(data) >= j + 16:
            samples = int.from_bytes(data[j + 12:j + 16], "big")
        elif i < 0 and b"moov" in data:
            samples = 0
    if codec is not None and not codec.replace("_", "").replace("/", "").isalnum():
        codec = None
    return codec, samples


def _cannot_open(path: Path, suffix: str) -> VideoError:
    container = suffix.lstrip(".")
    if _header_matches(path, suffix) is False:
        return _fail(path, f"the file is corrupt or is not a {container} video (its header is not a {container} "
                     "header)", "check the file is complete; if it is a video in another format, "
                     + _REENCODE.format(path=path))
    codec, samples = _sniff(path, suffix)
    if samples == 0:
        return _fail(path, f"the {container} file holds zero video frames", "record or export the video again, "
                     "or " + _REENCODE.format(path=path))
    if codec and codec.upper().replace("V_", "").split("/")[0] in _COMMON_CODECS:
        return _fail(path, f"the {container} file (codec {codec!r}) holds no decodable video frames: it is empty "
                     "(zero frames) or truncated", "record or export the video again, or " + _REENCODE.format(path=path))
    if codec:
        return _fail(path, f"its video codec {codec!r} cannot be decoded by this OpenCV build (unsupported codec), "
                     "or the file is truncated", _REENCODE.format(path=path))
    return _fail(path, f"OpenCV cannot open this {container} file: it has no decodable video stream (zero frames), "
                 "is truncated or corrupt, or uses a codec this OpenCV build cannot decode", _REENCODE.format(path=path))


def _check_file(path: Path) -> str:
    if not path.exists():
        raise _fail(path, "the file does not exist", f"check the path (relative paths start at {os.getcwd()})")
    if path.is_dir():
        raise _fail(path, "it is a directory, not a video file", "pass the path of a video file inside it")
    suffix = path.suffix.lower()
    if suffix not in VIDEO_EXTENSIONS:
        raise _fail(path, f"unsupported container {suffix or '(no extension)'!r}; readable containers are "
                    f"{', '.join(VIDEO_EXTENSIONS)}", _REENCODE.format(path=path))
    size = path.stat().st_size
    if size == 0:
        raise _fail(path, "the file is empty (0 bytes)",
                    "the recording, export or download did not finish: record or download it again")
    return suffix


def _sample_indices(times: Sequence[float], duration: float, fps: Optional[float], max_frames: int) -> List[int]:
    """Indices of the frames to keep: one per ``1/fps`` seconds, at most ``max_frames`` spread evenly."""
    n = len(times)
    if n == 0:
        return []
    if fps is None or fps <= 0:
        targets = list(times)
    else:
        step = 1.0 / fps
        count = max(1, int(math.floor((duration - 1e-6) / step)) + 1)  # every target time < duration
        targets = [k * step for k in range(count)]
    if len(targets) > max_frames:
        if max_frames == 1:
            targets = [times[0]]
        else:
            last = times[-1]
            targets = [times[0] + (last - times[0]) * k / (max_frames - 1) for k in range(max_frames)]
    arr = np.asarray(times, dtype=float)
    chosen: List[int] = []
    for target in targets:
        # the frame on screen at time `target`: the last one that starts at or before it
        i = int(np.searchsorted(arr, target + 1e-6, side="right")) - 1
        i = min(max(i, 0), n - 1)
        if not chosen or i > chosen[-1]:
            chosen.append(i)
    return chosen


def _fit(frame: np.ndarray, max_pixels: int) -> np.ndarray:
    import cv2

    h, w = frame.shape[:2]
    if w * h <= max_pixels:
        return frame
    scale = math.sqrt(max_pixels / float(w * h))
    nw, nh = max(1, int(w * scale)), max(1, int(h * scale))
    while nw * nh > max_pixels:  # floating-point slack
        if nw >= nh:
            nw -= 1
        else:
            nh -= 1
    return cv2.resize(frame, (nw, nh), interpolation=cv2.INTER_AREA)


def _as_rgb(frame: np.ndarray) -> np.ndarray:
    import cv2

    if frame.ndim == 2:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2RGB)
    if frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)


def _read_gif(path: Path, fps, max_frames, max_pixels) -> VideoClip:
    try:
        image = Image.open(path)
    except Image.DecompressionBombError as error:
        # A corrupt header often declares an absurd canvas; Pillow refuses it before decoding.
        raise _fail(path, f"the gif is corrupt: its header declares an impossible size ({error})",
                    _REENCODE.format(path=path)) from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as error:
        raise _fail(path, f"the gif is corrupt or not a gif ({error})", _REENCODE.format(path=path)) from None
    frames: List[np.ndarray] = []
    durations: List[float] = []
    try:
        with image:
            for frame in ImageSequence.Iterator(image):
                ms = frame.info.get("duration") or 0
                durations.append((ms if ms > 10 else 100) / 1000.0)  # browsers show 0-10 ms frames for 100 ms
                frames.append(np.asarray(frame.convert("RGB")))
    except (OSError, ValueError, EOFError, SyntaxError, Image.DecompressionBombError) as error:
        if not frames:
            raise _fail(path, f"the gif is corrupt: no frame decodes ({error})", _REENCODE.format(path=path)) from None
    if not frames:
        raise _fail(path, "the gif holds zero frames", _REENCODE.format(path=path))
    times = list(np.concatenate([[0.0], np.cumsum(durations)[:-1]]))
    duration = float(sum(durations))
    keep = _sample_indices(times, duration, fps, max_frames)
    src_h, src_w = frames[0].shape[:2]
    median = float(np.median(durations))
    return VideoClip(
        frames=[_fit(frames[i], max_pixels) for i in keep],
        times=[float(times[i]) for i in keep],
        source_fps=1.0 / median if median > 0 else 0.0,
        source_size=(int(src_w), int(src_h)),
        duration=duration,
        path=str(path),
        source_frames=len(frames),
        info={"container": "gif", "reader": "pillow"},
    )


def _fourcc(cap) -> str:
    import cv2

    code = int(cap.get(cv2.CAP_PROP_FOURCC) or 0)
    text = "".join(chr((code >> (8 * k)) & 0xFF) for k in range(4))
    return text if text.isprintable() and text.strip() else "?"


def _open(path: Path):
    # FFmpeg's own log lines ("moov atom not found") would precede our one-line error; OpenCV reads this
    # variable when its FFmpeg backend first starts, and the user's own setting wins
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    import cv2

    previous = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        if not cap.isOpened():
            cap.release()
            cap = cv2.VideoCapture(str(path))
    finally:
        cv2.utils.logging.setLogLevel(previous)
    return cap


def _read_opencv(path: Path, suffix: str, fps, max_frames, max_pixels) -> VideoClip:
    import cv2

    container = suffix.lstrip(".")
    cap = _open(path)
    if not cap.isOpened():
        cap.release()
        raise _cannot_open(path, suffix)
    try:
        src_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if not (0.0 < src_fps < 1000.0) or math.isnan(src_fps):
            src_fps = 0.0
        codec = _fourcc(cap)
        # pass 1: count the frames that really decode and note their timestamps
        stamps: List[float] = []
        while cap.grab():
            stamps.append(float(cap.get(cv2.CAP_PROP_POS_MSEC) or 0.0) / 1000.0)
    finally:
        cap.release()
    n = len(stamps)
    if n == 0:
        if _header_matches(path, suffix) is False:
            raise _cannot_open(path, suffix)
        raise _fail(path, f"the {container} file opened but holds zero decodable video frames (codec "
                    f"{codec!r}): it has no video stream, is truncated, or its codec is not supported by this "
                    "OpenCV build", _REENCODE.format(path=path))
    if src_fps > 0:
        times = [i / src_fps for i in range(n)]
        duration = n / src_fps
    else:
        monotonic = all(b > a for a, b in zip(stamps, stamps[1:]))
        if n > 1 and monotonic:
            times = [s - stamps[0] for s in stamps]
            step = float(np.median(np.diff(times)))
            src_fps = 1.0 / step if step > 0 else 0.0
            duration = times[-1] + step
        else:
            src_fps = 25.0  # no usable timing in the file: assume a common rate
            times = [i / src_fps for i in range(n)]
            duration = n / src_fps
    keep = _sample_indices(times, duration, fps, max_frames)
    wanted = set(keep)
    frames: List[np.ndarray] = []
    cap = _open(path)
    try:
        index = 0
        last = keep[-1]
        while index <= last and cap.grab():
            if index in wanted:
                ok, frame = cap.retrieve()
                if ok and frame is not None:
                    frames.append(_fit(_as_rgb(frame), max_pixels))
                else:
                    wanted.discard(index)
            index += 1
    finally:
        cap.release()
    kept = [i for i in keep if i in wanted][: len(frames)]
    if not frames:
        raise _fail(path, f"no frame of the {container} file decodes (codec {codec!r})", _REENCODE.format(path=path))
    first = frames[0]
    src_w, src_h = first.shape[1], first.shape[0]
    cap = _open(path)
    try:
        w = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH) or 0)
        h = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0)
        if w > 0 and h > 0:
            src_w, src_h = w, h
    finally:
        cap.release()
    return VideoClip(
        frames=frames,
        times=[float(times[i]) for i in kept],
        source_fps=src_fps,
        source_size=(int(src_w), int(src_h)),
        duration=float(duration),
        path=str(path),
        source_frames=n,
        info={"container": container, "codec": codec, "reader": "opencv"},
    )


def read_video(
    path: Union[str, os.PathLike],
    fps: Optional[float] = 2.0,
    max_frames: int = 16,
    max_pixels: int = 448 * 448,
) -> VideoClip:
    """Read a video file into a :class:`VideoClip` of RGB frames.

    Args:
        path: an ``.mp4``, ``.m4v``, ``.mov``, ``.webm``, ``.mkv``, ``.avi`` or ``.gif`` file.
        fps: sampling rate [frames/s]: one frame every ``1/fps`` seconds, never
            the same frame twice (a source slower than ``fps`` gives all its
            frames). ``None`` keeps every frame of the source.
        max_frames: at most this many frames; when the rate gives more, this many
            are spread evenly from the first to the last frame (order kept).
        max_pixels: each frame is shrunk, keeping its aspect ratio, until
            ``width * height <= max_pixels``; smaller frames are left as they are.

    Raises:
        VideoError: missing, empty, corrupt or unreadable file, zero frames, or
            a container or codec that cannot be decoded here.
    """
    if fps is not None and not (fps > 0):
        raise VideoError(f"fps must be a positive number of frames per second or None, got {fps!r}")
    if int(max_frames) < 1:
        raise VideoError(f"max_frames must be at least 1, got {max_frames!r}")
    if int(max_pixels) < 1:
        raise VideoError(f"max_pixels must be at least 1, got {max_pixels!r}")
    p = Path(os.fspath(path)).expanduser()
    suffix = _check_file(p)
    if suffix == ".gif":
        return _read_gif(p, fps, int(max_frames), int(max_pixels))
    return _read_opencv(p, suffix, fps, int(max_frames), int(max_pixels))


_FORMATS = {"jpeg": (".jpg", "image/jpeg"), "jpg": (".jpg", "image/jpeg"), "png": (".png", "image/png"),
            "webp": (".webp", "image/webp")}


def frames_to_data_urls(frames: Sequence[np.ndarray], fmt: str = "jpeg", quality: int = 90) -> List[str]:
    """Encode RGB frames as ``data:image/...;base64,...`` URLs (jpeg, png or webp)."""
    import cv2

    key = fmt.lower()
    if key not in _FORMATS:
        raise VideoError(f"unsupported image format {fmt!r}; use one of {sorted(set(_FORMATS) - {'jpg'})}")
    ext, mime = _FORMATS[key]
    params: List[int] = []
    if ext == ".jpg":
        params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    elif ext == ".webp":
        params = [cv2.IMWRITE_WEBP_QUALITY, int(quality)]
    urls = []
    for frame in frames:
        array = np.asarray(frame)
        if array.ndim != 3 or array.shape[2] not in (3, 4):
            raise VideoError(f"frames must be H x W x 3 RGB arrays (height, width, colour), got shape {array.shape}")
        bgr = cv2.cvtColor(np.ascontiguousarray(array[..., :3], dtype=np.uint8), cv2.COLOR_RGB2BGR)
        ok, data = cv2.imencode(ext, bgr, params)
        if not ok:
            raise VideoError(f"OpenCV could not encode a frame as {fmt}")
        urls.append(f"data:{mime};base64,{base64.b64encode(data.tobytes()).decode('ascii')}")
    return urls
