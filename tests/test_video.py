"""Video input: every container, sampling (rate, cap, coverage, order), the pixel budget, bad inputs."""

from __future__ import annotations

import base64
import math
import os

import cv2
import numpy as np
import pytest
from PIL import Image

from dv2s_gym.pipeline.video import VideoClip, VideoError, frames_to_data_urls, read_video

FPS = 10
N = 30          # 3 s at 10 frames/s
W, H = 64, 48


def _frame(i: int, w: int = W, h: int = H) -> np.ndarray:
    """Frame i: a bright bar at x = 2 i on a dark grey canvas (survives lossy codecs and resizing)."""
    frame = np.full((h, w, 3), 40, np.uint8)
    x = int(round(2 * i * w / W)) % w
    frame[:, x:x + max(2, w // W * 2)] = 230
    return frame


def _index(frame: np.ndarray) -> int:
    columns = frame.astype(float).mean(axis=(0, 2))
    bright = np.nonzero(columns > (columns.max() + columns.min()) / 2)[0]
    centre = (float(bright.mean()) + 0.5) * W / frame.shape[1] - 0.5   # bar centre in the original 64-px frame
    return int(round((centre - 0.5) / 2))


def _write(path, fourcc: str, n: int = N, fps: float = FPS, w: int = W, h: int = H) -> str:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
    assert writer.isOpened(), f"this OpenCV cannot write {fourcc} into {path}"
    for i in range(n):
        writer.write(cv2.cvtColor(_frame(i, w, h), cv2.COLOR_RGB2BGR))
    writer.release()
    return str(path)


def _gif(path, n: int = N, ms: int = 100) -> str:
    images = [Image.fromarray(_frame(i)) for i in range(n)]
    images[0].save(path, save_all=True, append_images=images[1:], duration=ms, loop=0)
    return str(path)


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    d = tmp_path_factory.mktemp("videos")
    return {
        "mp4": _write(d / "clip.mp4", "mp4v"),
        "avi": _write(d / "clip.avi", "MJPG"),
        "webm": _write(d / "clip.webm", "VP80"),
        "mkv": _write(d / "clip.mkv", "VP80"),
        "gif": _gif(d / "clip.gif"),
    }


# ----------------------------------------------------------------------------- containers
@pytest.mark.parametrize("kind", ["mp4", "avi", "webm", "mkv", "gif"])
def test_every_container_reads(clips, kind):
    clip = read_video(clips[kind], fps=None, max_frames=1000)
    assert isinstance(clip, VideoClip)
    assert len(clip) == N == clip.source_frames
    assert clip.source_size == (W, H) and clip.size == (W, H)
    assert clip.source_fps == pytest.approx(FPS, rel=0.01)
    assert clip.duration == pytest.approx(N / FPS, rel=0.01)
    assert clip.path == clips[kind]
    for f in clip.frames:
        assert f.dtype == np.uint8 and f.shape == (H, W, 3)
    assert [_index(f) for f in clip.frames] == list(range(N))
    assert clip.times == pytest.approx([i / FPS for i in range(N)], abs=1e-6)


def test_rgb_channel_order(tmp_path):
    path = tmp_path / "red.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5, (32, 32))
    for _ in range(3):
        writer.write(np.dstack([np.zeros((32, 32)), np.zeros((32, 32)), np.full((32, 32), 255)]).astype(np.uint8))
    writer.release()
    frame = read_video(path).frames[0]
    assert frame[..., 0].mean() > 200 and frame[..., 2].mean() < 50  # red in RGB


# ----------------------------------------------------------------------------- sampling
@pytest.mark.parametrize("kind", ["webm", "gif"])
def test_fixed_rate(clips, kind):
    clip = read_video(clips[kind], fps=2.0, max_frames=100)
    assert clip.times == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0, 2.5], abs=1e-6)
    assert [_index(f) for f in clip.frames] == [0, 5, 10, 15, 20, 25]
    assert clip.fps == pytest.approx(2.0)


def test_default_rate_is_two_per_second(clips):
    clip = read_video(clips["mp4"])
    assert len(clip) == 6 and clip.fps == pytest.approx(2.0)


def test_cap_spreads_frames_over_the_whole_video_in_order(clips):
    clip = read_video(clips["avi"], fps=10.0, max_frames=4)
    idx = [_index(f) for f in clip.frames]
    assert len(clip) == 4
    assert idx[0] == 0 and idx[-1] == N - 1           # coverage: first and last frame
    assert idx == sorted(idx) and len(set(idx)) == 4  # order, no repeats
    gaps = np.diff(idx)
    assert gaps.max() - gaps.min() <= 1               # evenly spread
    assert clip.times == sorted(clip.times)


def test_cap_of_one_frame(clips):
    clip = read_video(clips["webm"], fps=10.0, max_frames=1)
    assert len(clip) == 1 and clip.times == [0.0]


def test_rate_above_source_never_repeats_a_frame(clips):
    clip = read_video(clips["mkv"], fps=25.0, max_frames=1000)
    assert [_index(f) for f in clip.frames] == list(range(N))


def test_all_frames_with_fps_none(clips):
    assert len(read_video(clips["mp4"], fps=None, max_frames=1000)) == N


def test_long_video_keeps_coverage(tmp_path):
    path = _write(tmp_path / "long.avi", "MJPG", n=30, fps=1.0)  # 30 s
    clip = read_video(path, fps=2.0, max_frames=16)
    assert len(clip) == 16
    assert clip.times[0] == 0.0 and clip.times[-1] == pytest.approx(29.0)
    assert all(b > a for a, b in zip(clip.times, clip.times[1:]))


def test_gif_frame_durations(tmp_path):
    path = _gif(tmp_path / "slow.gif", n=6, ms=500)
    clip = read_video(path, fps=None)
    assert clip.source_fps == pytest.approx(2.0)
    assert clip.duration == pytest.approx(3.0)
    assert clip.times == pytest.approx([0, 0.5, 1.0, 1.5, 2.0, 2.5])


# ----------------------------------------------------------------------------- resizing
def test_resize_keeps_aspect_ratio_under_the_budget(tmp_path):
    path = _write(tmp_path / "wide.avi", "MJPG", n=4, w=640, h=360)
    clip = read_video(path, max_pixels=100 * 100)
    w, h = clip.size
    assert w * h <= 100 * 100
    assert w / h == pytest.approx(640 / 360, rel=0.03)
    assert w * h > 0.9 * 100 * 100                     # uses the budget
    assert clip.source_size == (640, 360)


def test_default_budget(tmp_path):
    path = _write(tmp_path / "big.avi", "MJPG", n=2, w=800, h=600)
    w, h = read_video(path).size
    assert w * h <= 448 * 448 and w / h == pytest.approx(800 / 600, rel=0.02)


def test_small_frames_are_not_enlarged(clips):
    assert read_video(clips["webm"], max_pixels=10 ** 6).size == (W, H)


# ----------------------------------------------------------------------------- bad inputs
def _error(path, **kwargs) -> str:
    with pytest.raises(VideoError) as info:
        read_video(path, **kwargs)
    message = str(info.value)
    assert str(path) in message and "Fix:" in message
    return message


def test_missing_file(tmp_path):
    assert "does not exist" in _error(tmp_path / "nope.mp4")


def test_directory(tmp_path):
    (tmp_path / "dir.mp4").mkdir()
    assert "directory" in _error(tmp_path / "dir.mp4")


def test_empty_file(tmp_path):
    path = tmp_path / "empty.webm"
    path.write_bytes(b"")
    assert "empty (0 bytes)" in _error(path)


def test_corrupt_file(tmp_path):
    path = tmp_path / "noise.mp4"
    path.write_bytes(os.urandom(4096))
    message = _error(path)
    assert "corrupt" in message and "ffmpeg" in message


def test_truncated_file(tmp_path, clips):
    path = tmp_path / "cut.webm"
    path.write_bytes(open(clips["webm"], "rb").read()[:60])
    message = _error(path)
    assert "truncated" in message and "ffmpeg" in message


def test_zero_frames(tmp_path):
    path = _write(tmp_path / "none.avi", "MJPG", n=0)
    message = _error(path)
    assert "zero" in message and "frames" in message


def test_zero_frames_mp4(tmp_path):
    path = _write(tmp_path / "none.mp4", "mp4v", n=0)
    assert "zero" in _error(path)


def test_unsupported_codec(tmp_path, clips):
    path = tmp_path / "odd.avi"
    path.write_bytes(open(clips["avi"], "rb").read().replace(b"MJPG", b"ZZZZ"))
    message = _error(path)
    assert "codec" in message and "ZZZZ" in message and "re-encode" in message


@pytest.mark.parametrize("name", ["clip.txt", "clip.flv", "clip"])
def test_unsupported_container(tmp_path, clips, name):
    path = tmp_path / name
    path.write_bytes(open(clips["mp4"], "rb").read())
    message = _error(path)
    assert "unsupported container" in message and "ffmpeg" in message


@pytest.mark.parametrize("seed", range(20))
def test_corrupt_gif(tmp_path, seed):
    path = tmp_path / "bad.gif"
    path.write_bytes(b"GIF89a" + np.random.default_rng(seed).bytes(64))
    assert "gif" in _error(path)


def test_gif_header_with_impossible_size(tmp_path):
    # 60000 x 60000 pixels declared: Pillow's decompression-bomb guard fires before any decoding.
    path = tmp_path / "huge.gif"
    size = (60000).to_bytes(2, "little") * 2
    screen = size + bytes(3)  # no global colour table
    descriptor = b"\x2c" + bytes(4) + size + bytes(1)
    path.write_bytes(b"GIF89a" + screen + descriptor + bytes(32))
    assert "impossible size" in _error(path)


def test_errors_are_value_errors():
    assert issubclass(VideoError, ValueError)


@pytest.mark.parametrize("kwargs", [{"fps": 0}, {"fps": -1.0}, {"max_frames": 0}, {"max_pixels": 0}])
def test_bad_arguments(clips, kwargs):
    with pytest.raises(ValueError):
        read_video(clips["mp4"], **kwargs)


# ----------------------------------------------------------------------------- data URLs
@pytest.mark.parametrize("fmt,mime,magic", [("jpeg", "image/jpeg", b"\xff\xd8"), ("png", "image/png", b"\x89PNG")])
def test_data_urls(clips, fmt, mime, magic):
    frames = read_video(clips["webm"], fps=1.0).frames
    urls = frames_to_data_urls(frames, fmt=fmt)
    assert len(urls) == len(frames) == 3
    for url, frame in zip(urls, frames):
        head, data = url.split(",", 1)
        assert head == f"data:{mime};base64"
        raw = base64.b64decode(data)
        assert raw.startswith(magic)
        decoded = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
        assert decoded.shape == frame.shape
        assert abs(float(decoded.mean()) - float(frame.mean())) < 4


def test_data_url_format_errors():
    with pytest.raises(ValueError):
        frames_to_data_urls([np.zeros((4, 4, 3), np.uint8)], fmt="bmpx")
    with pytest.raises(ValueError):
        frames_to_data_urls([np.zeros((4, 4), np.uint8)])
    assert math.isclose(len(frames_to_data_urls([])), 0)
