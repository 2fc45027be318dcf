"""A stall's failure video covers the stall, not just its first second.

The stall is the first one a fixed mining run gives: the shipped ``dv2s-ppo`` policy, 4 random scenes
(seed 0), no reference; its failure time is when the ego starts standing.
"""

from __future__ import annotations

import json
import math

import pytest

from dv2s_gym.mining.conversion.failure_video import stall_end, write_failure_video
from dv2s_gym.mining.monitors import DEFAULT_STALL_SECONDS, STALL_SPEED, MonitorSettings
from dv2s_gym.pipeline.video import read_video

FPS = 5  # the env's default policy frequency


@pytest.fixture(scope="module")
def stall(tmp_path_factory) -> dict:
    from mining_helpers import mine

    out = tmp_path_factory.mktemp("mine") / "run"
    mine("dv2s-ppo", out=out, budget=4, sampler="random", workers=1, reference=None, progress=False, reports=False,
         seed=0)
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    stalls = [r for r in records if (r.get("failure") or {}).get("type") == "stall"]
    assert stalls, [r.get("failure") for r in records]
    return min(stalls, key=lambda r: r["index"])


@pytest.mark.slow
def test_a_stall_video_runs_from_before_the_stall_through_it(stall, tmp_path):
    written = write_failure_video(stall, tmp_path / "stall.webm", policy="dv2s-ppo", before=4.0, after=1.0)
    k = stall["failure"]["step"]
    assert written.failure_frame == k and written.first == max(0, k - 4 * FPS)
    # the monitor needs stall_seconds of standing: the clip holds all of them, then one second more
    needed = math.ceil(DEFAULT_STALL_SECONDS * FPS)
    last = stall_end(written.trace, k, needed)
    assert last == k + needed - 1  # a stall the monitor flagged stands for the whole duration
    for frame in range(k, last + 1):
        assert written.trace.states[frame]["ego"][3] < STALL_SPEED
    assert written.last == last + FPS
    assert written.last - k > 4 * FPS  # the old window ended 1 s after the stall began
    clip = read_video(written.path, fps=None, max_frames=1000, max_pixels=10**7)
    assert len(clip.frames) == written.frames == written.last - written.first + 1


@pytest.mark.slow
def test_a_shorter_monitor_stall_duration_shortens_the_clip(stall, tmp_path):
    written = write_failure_video(stall, tmp_path / "stall.webm", policy="dv2s-ppo", before=1.0, after=0.0,
                                  monitor=MonitorSettings(stall_seconds=2.0))
    k = stall["failure"]["step"]
    assert (written.first, written.last) == (k - FPS, k + 2 * FPS - 1)
