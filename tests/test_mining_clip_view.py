"""A failure clip's view holds the actor the failure involves, however far ahead it is, and the ``bev`` Driving
Record Analyzer still reads the clip: a stopped car 90 m ahead that the ego drives into (the plain 480 x 480 view
at 5.5 px/m holds about 44 m around the ego, so the car was out of it for the clip's first two seconds)."""

from __future__ import annotations

import os
from types import SimpleNamespace

import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")

from dv2s_gym.mining.conversion.failure_video import ACTOR_MARGIN, VIDEO_CONFIG, clip_camera, write_failure_video  # noqa: E402

SCENARIO = "highway_lead_vehicle_stopped"
PARAMS = {"ego_speed": 25.0, "stopped_gap": 90.0, "traffic_speed": 22.0}
SCALE = VIDEO_CONFIG["scaling"]


def _pixel(camera: dict, offset) -> tuple:
    """Where a point ``offset`` metres from the ego is drawn in a view (x right, y down, as highway-env draws)."""
    width = camera.get("screen_width", VIDEO_CONFIG["screen_width"])
    height = camera.get("screen_height", VIDEO_CONFIG["screen_height"])
    cx, cy = camera.get("centering_position", [0.5, 0.5])
    return cx * width + offset[0] * SCALE, cy * height + offset[1] * SCALE, width, height


def _inside(camera: dict, offset, margin: float) -> bool:
    x, y, width, height = _pixel(camera, offset)
    m = margin * SCALE - 1
    return m <= x <= width - m and m <= y <= height - m


def _trace(*paths):
    return SimpleNamespace(states=[{"ego": [10.0 * k, 0.0, 0.0, 10.0], "car": list(p)} for k, p in enumerate(paths)])


def test_the_view_looks_ahead_only_as_far_as_the_actor_needs():
    near = _trace([30.0, 0.0, 0.0, 0.0], [40.0, 0.0, 0.0, 0.0])  # 30 m ahead: the plain view holds it
    assert clip_camera(near, "car", 0, 1) == {} and clip_camera(near, None, 0, 1) == {}
    far = _trace([65.0, 0.0], [70.0, 3.5], [75.0, 0.0])  # 65, 60, 55 m ahead: the plain view does not
    camera = clip_camera(far, "car", 0, 2)  # the ego shifted back in a frame of the plain size
    assert (camera["screen_width"], camera["screen_height"]) == (480, 480) and camera["centering_position"][0] < 0.3
    for k, state in enumerate(far.states):
        offset = (state["car"][0] - state["ego"][0], state["car"][1] - state["ego"][1])
        assert not _inside({}, offset, 0) and _inside(camera, offset, ACTOR_MARGIN)
    assert _inside(camera, (-10.0, 0.0), 0)  # a little behind the ego stays in view
    ahead = _trace([120.0, -20.0])  # far ahead and to the side: the frame grows that way and narrows across
    wide = clip_camera(ahead, "car", 0, 0)
    assert _inside(wide, (120.0, -20.0), ACTOR_MARGIN) and wide["screen_width"] > VIDEO_CONFIG["screen_width"]
    assert wide["screen_height"] < VIDEO_CONFIG["screen_height"] and _inside(wide, (-10.0, 0.0), 0)
    assert wide["screen_width"] * wide["screen_height"] <= 1.1 * 480 * 480  # about the plain view's pixels
    behind = _trace([-70.0, 0.0])  # a car coming from behind: the view looks back
    assert _inside(clip_camera(behind, "car", 0, 0), (-70.0, 0.0), ACTOR_MARGIN)


def test_a_stall_clip_holds_the_car_the_ego_stood_behind():
    from dv2s_gym.mining.conversion.failure_video import VideoSettings, _camera
    from scenario_bank.records import Failure

    # the ego stands; a car stopped 60 m ahead in its lane, another cruising by in the next lane
    states = [{"ego": [0.0, 0.0, 0.0, 0.0], "blocker": [60.0, 0.3, 0.0, 0.0], "passer": [-20.0 + 4 * k, 4.0, 0.0, 20.0]}
              for k in range(40)]
    trace = SimpleNamespace(states=states, events=[], config={"policy_frequency": 5})
    stall = Failure("stall", 2.0, 10)
    camera = _camera(trace, stall, 10, 5.0, True, VideoSettings(), 40)
    assert not _inside({}, (60.0, 0.3), 0) and _inside(camera, (60.0, 0.3), ACTOR_MARGIN)


@pytest.fixture(scope="module")
def far_failure():
    """A real episode: ``keep_lane`` drives at 25 m/s into a car stopped 90 m ahead (4 s before the impact)."""
    from policies.evaluation import make_eval_env, run_episode
    from policies.registry import load_policy

    env = make_eval_env([SCENARIO])
    try:
        policy = load_policy("keep_lane")
        policy.bind([env])
        result, trace = run_episode(env, policy, SCENARIO, 3, params=PARAMS)
    finally:
        env.close()
    hit = [e for e in trace.events if e["kind"] == "collision"]
    assert result.collided and hit and hit[0]["actors"] == ["ego", "stopped"]
    step = int(round(hit[0]["time"] * 5))
    return {"index": 0, "scenario": SCENARIO, "seed": 3, "params": PARAMS,
            "result": {"trajectory_hash": result.trajectory_hash, "steps": len(trace.actions)},
            "failure": {"type": "collision", "step": step, "time": hit[0]["time"], "with": "stopped",
                        "with_kind": "car", "kind": "collision:rear_end"}}


@pytest.mark.slow
def test_a_failure_clip_shows_the_far_actor_and_the_analyzer_reads_it(far_failure, tmp_path):
    from dv2s_gym.pipeline.dra.bev import analyze_bev_file
    from dv2s_gym.pipeline.video import read_video

    written = write_failure_video(far_failure, tmp_path / "failure.webm", policy="keep_lane", before=4.0, after=1.0)
    config = written.trace.config
    camera = {key: config[key] for key in ("screen_width", "screen_height", "centering_position")}
    offsets = []
    for frame in range(written.first, min(written.last, len(written.trace.states) - 1) + 1):
        ego, car = written.trace.states[frame]["ego"], written.trace.states[frame]["stopped"]
        offsets.append((car[0] - ego[0], car[1] - ego[1]))
    assert max(o[0] for o in offsets) > 80  # the cause is far ahead at the clip's start
    assert sum(not _inside({}, o, 0) for o in offsets) >= 5  # the plain view missed it in those frames
    assert all(_inside(camera, o, ACTOR_MARGIN) for o in offsets)  # this view holds it in every frame
    clip = read_video(written.path, fps=None, max_frames=1000, max_pixels=10**7)
    assert len(clip.frames) == written.frames
    assert clip.frames[0].shape[:2] == (camera["screen_height"], camera["screen_width"])
    # the stopped car's body colour is drawn where the trace puts it in the first frame (90 m ahead)
    x, y, _, _ = _pixel(camera, offsets[0])
    patch = clip.frames[0][int(y) - 3:int(y) + 4, int(x) - 8:int(x) + 9].reshape(-1, 3).astype(int)
    grey = (abs(patch - patch.mean(axis=1, keepdims=True)) < 12).all(axis=1)
    assert (~grey).sum() > 20, "no coloured vehicle body at the stopped car's place"
    analysis = analyze_bev_file(str(written.path))
    assert abs(analysis.debug["scale"]["px_per_m"] - SCALE) / SCALE < 0.05  # the scale it measures is kept
    ahead = [t for t in analysis.tracks if t.get("kind") in ("car", "truck")]
    assert ahead, analysis.tracks
    assert "stopped" in analysis.description.lower() or any("stop" in str(t).lower() for t in ahead), (
        analysis.description, ahead)
