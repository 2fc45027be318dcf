"""The ``bev`` Driving Record Analyzer: synthetic renders (fast), rendered bank clips and stock
highway-env clips (slow), and videos that are not bird's-eye renders."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np
import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
if os.environ.get("SDL_VIDEODRIVER") == "dummy":
    os.environ["SDL_VIDEODRIVER"] = "offscreen"

from dv2s_gym.pipeline.dra.bev import BevAnalysis, NotBirdsEyeError, analyze_bev, analyze_bev_file  # noqa: E402
from dv2s_gym.pipeline.metrics import hallucination_rate, scs  # noqa: E402
from dv2s_gym.pipeline.video import VideoClip, read_video  # noqa: E402
from envs.recording import VideoWriter  # noqa: E402
from scenario_bank.elements import Elements, element_set  # noqa: E402

SCS_MIN, HR_MAX = 0.9, 0.1

# ----------------------------------------------------------------------------- synthetic renders
# Drawn like highway-env: 5.5 px/m, grey canvas, 1-px white lines (stripes 3 m every 4.33 m),
# vehicles with a dark outline and lighter headlights, the camera on the ego, north up.
SCALE = 5.5
GREY, WHITE = (100, 100, 100), (255, 255, 255)
EGO, CAR = (50, 200, 0), (100, 200, 255)


def _lighten(color):
    return tuple(min(int(c / 0.68), 255) for c in color)


def _vehicle(img, cx, cy, color, heading=0.0, length=4.5, width=2.0):
    """A rectangle centred at (cx, cy) px, heading in map radians (0 = east), headlights at the front."""
    c, s = math.cos(heading), -math.sin(heading)   # screen direction (y down)
    hl, hw = length * SCALE / 2, width * SCALE / 2

    def corner(a, b):
        return (cx + a * c - b * s, cy + a * s + b * c)

    body = np.array([corner(-hl, -hw), corner(hl, -hw), corner(hl, hw), corner(-hl, hw)], np.int32)
    cv2.fillPoly(img, [body], color)
    for side in (-0.55, 0.55):
        lamp = np.array([corner(hl - 4, side * hw - 1.5), corner(hl - 1, side * hw - 1.5),
                         corner(hl - 1, side * hw + 1.5), corner(hl - 4, side * hw + 1.5)], np.int32)
        cv2.fillPoly(img, [lamp], _lighten(color))
    cv2.polylines(img, [body], True, (60, 60, 60), 1)


def _hline(img, y, x0, x1, striped, phase_px):
    y = int(round(y))
    if not striped:
        cv2.line(img, (int(x0), y), (int(x1), y), WHITE, 1)
        return
    period, stripe = 4.33 * SCALE, 3.0 * SCALE
    start = x0 - ((x0 - phase_px) % period)
    x = start
    while x < x1:
        a, b = max(x, x0), min(x + stripe, x1)
        if b > a:
            cv2.line(img, (int(round(a)), y), (int(round(b)), y), WHITE, 1)
        x += period



def _lead_frame(size: int, ego_x: float, lead_x: float) -> np.ndarray:
    """One frame of a four-lane highway (dashed inner lines scrolling with the ego) with the ego at the centre, in
    lane 2, and a car ``lead_x - ego_x`` metres ahead of it in its lane."""
    cx = cy = size / 2
    lane = 3.5 * SCALE
    ys = [cy - 1.5 * lane + k * lane for k in range(5)]      # ego between lines 1 and 2 (lane index 1)
    img = np.full((size, size, 3), GREY, np.uint8)
    for k, y in enumerate(ys):
        _hline(img, y, 0, size, striped=0 < k < 4, phase_px=cx - ego_x * SCALE)
    _vehicle(img, cx + (lead_x - ego_x) * SCALE, cy, CAR)
    _vehicle(img, cx, cy, EGO)
    return img

def _highway_lead_brakes(size: int = 400, seconds: float = 5.0, fps: float = 5.0) -> List[np.ndarray]:
    """Ego in lane 2 of 4 at 22 m/s; the car 30 m ahead in its lane brakes from 22 to 12 m/s at t = 2 s."""
    frames = []
    ego_x, lead_x, v_e, v_l = 0.0, 30.0, 22.0, 22.0
    for i in range(int(seconds * fps) + 1):
        t = i / fps
        frames.append(_lead_frame(size, ego_x, lead_x))
        dt = 1.0 / fps
        a_l = -5.0 if 2.0 <= t < 4.0 else 0.0
        ego_x += v_e * dt
        lead_x += v_l * dt + 0.5 * a_l * dt * dt
        v_l = max(12.0, v_l + a_l * dt)
    return frames


def _highway_ego_slows_behind(size: int = 480, seconds: float = 6.0, fps: float = 5.0,
                              drop: Optional[int] = None) -> Tuple[List[np.ndarray], List[float], List[float]]:
    """Ego in lane 2 of 4 at 25 m/s braking at 7.5 m/s^2 to the 12 m/s of the car 40 m ahead in its lane,
    which holds its speed. ``drop``: that frame is lost (the interval around it lasts two frames, as in a
    decoded video that skipped one). Returns the frames, their times and the ego's true speeds."""
    frames, times, ego_speeds = [], [], []
    ego_x, lead_x, v_e, v_l = 0.0, 40.0, 25.0, 12.0
    dt = 1.0 / fps
    for i in range(int(seconds * fps) + 1):
        if i != drop:
            frames.append(_lead_frame(size, ego_x, lead_x))
            times.append(i * dt)
            ego_speeds.append(v_e)
        v_next = max(v_l, v_e - 7.5 * dt)
        ego_x += 0.5 * (v_e + v_next) * dt
        lead_x += v_l * dt
        v_e = v_next
    return frames, times, ego_speeds


def _junction(arms: Tuple[bool, bool, bool, bool], size: int = 400, n: int = 6) -> List[np.ndarray]:
    """A static junction of 1+1-lane roads (arms: left, right, up, down) with the ego on the left arm."""
    frames = []
    c = size / 2
    lane = 3.5 * SCALE
    jx0, jx1 = c + 40 - lane - 8, c + 40 + lane + 8     # junction box a bit right of the ego
    jy0, jy1 = c - lane - 8, c + lane + 8
    for _ in range(n):
        img = np.full((size, size, 3), GREY, np.uint8)
        for k in (-1, 0, 1):
            y = c + 0.5 * lane + k * lane - 0.5 * lane
            if arms[0]:
                _hline(img, y, 0, jx0, False, 0)
            if arms[1]:
                _hline(img, y, jx1, size, False, 0)
        for k in (-1, 0, 1):
            x = int(round(c + 40 + k * lane))
            if arms[2]:
                cv2.line(img, (x, 0), (x, int(jy0)), WHITE, 1)
            if arms[3]:
                cv2.line(img, (x, int(jy1)), (x, size), WHITE, 1)
        _vehicle(img, c - 40, c + 0.5 * lane, EGO)
        frames.append(img)
    return frames


def _clip(frames: List[np.ndarray], fps: float = 5.0, path: str = "") -> VideoClip:
    h, w = frames[0].shape[:2]
    return VideoClip(frames, [i / fps for i in range(len(frames))], fps, (w, h), len(frames) / fps, path)


def _dashcam(i: int, rng) -> np.ndarray:
    h, w = 240, 320
    img = np.zeros((h, w, 3), np.uint8)
    for y in range(h // 2):
        img[y] = (120 + y // 2, 160 + y // 3, 230)                      # sky
    img[h // 2:] = (90, 110, 80)                                        # verge
    road = np.array([[w // 2 - 20, h // 2], [w // 2 + 20, h // 2], [w, h], [0, h]], np.int32)
    cv2.fillPoly(img, [road], (105, 105, 105))
    noise = rng.integers(-14, 15, img[h // 2:].shape)
    img[h // 2:] = np.clip(img[h // 2:].astype(int) + noise, 0, 255).astype(np.uint8)
    for k in range(6):                                                   # dashes in perspective
        y0 = h // 2 + ((k * 20 + i * 5) % (h // 2))
        cv2.line(img, (w // 2, y0), (w // 2, min(h - 1, y0 + 8 + k)), (240, 240, 240), 1 + k // 2)
    cv2.rectangle(img, (140, 140), (180, 170), (40, 140, 40), -1)       # a green car ahead
    return img


# ----------------------------------------------------------------------------- fast tests
def test_synthetic_lead_vehicle_brakes():
    result = analyze_bev(_clip(_highway_lead_brakes()))
    assert isinstance(result, BevAnalysis)
    e = result.elements
    assert isinstance(e, Elements) and e == Elements.from_dict(e.to_dict())
    assert e.road == "highway"
    assert e.participants == ("car", "ego")
    assert ("car", "brake") in e.actions
    assert ("car", "ahead_of", "ego") in e.relations and ("car", "same_lane", "ego") in e.relations
    assert result.debug["lanes"] == 4
    speeds = [s for s in result.debug["ego_speed"] if s is not None]
    assert np.median(speeds) == pytest.approx(22.0, rel=0.12)   # from the stripes' motion
    sentences = [s for s in result.description.split(". ") if s]
    assert len(sentences) >= 2 and result.description.endswith("This scene takes place on a highway.")


def test_description_reads_back_as_the_elements():
    from dv2s_gym.pipeline.semantics.text import elements_from_text

    result = analyze_bev(_clip(_highway_lead_brakes()))
    assert element_set(elements_from_text(result.description)) == element_set(result.elements)


def test_question_is_answered():
    result = analyze_bev(_clip(_highway_lead_brakes()), question="What happens to the car in front?")
    assert result.answer and "brakes" in result.answer
    assert result.description.endswith(result.answer)
    assert analyze_bev(_clip(_highway_lead_brakes()), question="Did the ego vehicle crash?").answer.startswith("No")


@pytest.mark.parametrize("drop", [None, 12])
def test_ego_slowing_behind_a_steady_car(drop):
    """Dashed lines repeat every 4.33 m, so at 5 frames/s the ego's speed is only known modulo 21.65 m/s
    per interval (twice as many aliases over a lost frame): every alias the ego can reach must stay a
    candidate, else the chosen speed jumps by a period and the steady car ahead seems to brake."""
    frames, times, truth = _highway_ego_slows_behind(drop=drop)
    clip = VideoClip(frames, times, 5.0, (frames[0].shape[1], frames[0].shape[0]), times[-1] + 0.2, "")
    result = analyze_bev(clip)
    measured = np.array([np.nan if s is None else s for s in result.debug["ego_speed"]], float)
    lead = max(result.tracks, key=lambda trk: len(trk["frames"]))
    car = np.array([np.nan if s is None else s for s in lead["speed"]], float)
    scale = float(np.nanmedian(car)) / 12.0       # the measured scale's error, common to every speed
    assert 0.85 < scale < 1.15
    assert np.nanmax(np.abs(measured / scale - np.array(truth))) < 3.0, np.round(measured / scale, 1)
    assert (np.nanmax(car) - np.nanmin(car)) / np.nanmedian(car) < 0.15, np.round(car, 1)
    e = result.elements
    assert not {a for k, a in e.actions if k == "car"} & {"brake", "stop", "accelerate"}, result.description
    assert ("car", "keep_lane") in e.actions and ("car", "ahead_of", "ego") in e.relations and \
        ("car", "same_lane", "ego") in e.relations, result.description
    assert "slower car ahead of it in the same lane" in result.description


@pytest.mark.parametrize("arms,road", [((True, True, True, True), "intersection"),
                                       ((True, True, False, True), "t_junction"),
                                       ((True, True, False, False), "straight_road")])
def test_synthetic_road_layouts(arms, road):
    assert analyze_bev(_clip(_junction(arms))).elements.road == road


def test_sparse_clip_of_a_file_is_reread(tmp_path):
    path = tmp_path / "lead.webm"
    with VideoWriter(path, fps=5) as video:
        for frame in _highway_lead_brakes():
            video.write(frame)
    clip = read_video(path)                      # the pipeline's default: 2 frames/s, 16 frames
    result = analyze_bev(clip)
    assert "resampled_from" in result.debug["input"] and result.debug["input"]["frames"] == 26
    assert ("car", "brake") in result.elements.actions
    assert analyze_bev_file(path).elements == result.elements


@pytest.mark.parametrize("kind", ["noise", "dashcam", "empty_canvas"])
def test_not_birds_eye(kind):
    rng = np.random.default_rng(0)
    if kind == "noise":
        frames = [rng.integers(0, 256, (240, 320, 3), dtype=np.uint8) for _ in range(10)]
    elif kind == "dashcam":
        frames = [_dashcam(i, rng) for i in range(10)]
    else:
        frames = [np.full((240, 320, 3), GREY, np.uint8) for _ in range(10)]
    with pytest.raises(NotBirdsEyeError) as info:
        analyze_bev(_clip(frames))
    assert "--dra openai" in str(info.value) and "bird's-eye" in str(info.value)
    assert issubclass(NotBirdsEyeError, ValueError)


def test_not_birds_eye_video_file(tmp_path):
    rng = np.random.default_rng(1)
    path = tmp_path / "dashcam.avi"
    with VideoWriter(path, fps=5) as video:
        for i in range(10):
            video.write(_dashcam(i, rng))
    with pytest.raises(NotBirdsEyeError, match="dashcam.avi"):
        analyze_bev_file(path)


# ----------------------------------------------------------------------------- recorded bank clips (fast)
# Clips rendered once with make_bev_clips.render_clip(name, seed, path, seconds, size=320) and kept in
# tests/data/videos (no sidecar beside them): <scenario>_seed<seed>.webm.
FIXTURE_VIDEOS = sorted((Path(__file__).parent / "data" / "videos").glob("*.webm"))


KNOWN_CLIP_MISSES: Dict[str, float] = {}
"""Clips under SCS_MIN with their measured SCS: asserted exactly, so a fix or one more miss shows."""


@pytest.mark.parametrize("path", FIXTURE_VIDEOS, ids=[p.stem for p in FIXTURE_VIDEOS])
def test_recorded_bank_clip(path):
    name = path.stem.rsplit("_seed", 1)[0]
    truth = _ground_truth(name)
    result = analyze_bev_file(path)
    detail = (f"{name}: SCS {scs(truth, result.elements):.2f} HR {hallucination_rate(truth, result.elements):.2f} "
              f"{result.elements}")
    if name in KNOWN_CLIP_MISSES:
        assert scs(truth, result.elements) == pytest.approx(KNOWN_CLIP_MISSES[name]), detail
    else:
        assert scs(truth, result.elements) >= SCS_MIN, detail
    assert hallucination_rate(truth, result.elements) <= HR_MAX, detail


def test_recorded_clips_are_there():
    assert len(FIXTURE_VIDEOS) >= 3


# ----------------------------------------------------------------------------- rendered bank clips (slow)
# (scenario, seed, seconds, size), the seeds fixed in advance. The on-ramp merge happens 10-14 s in and the traffic car drives 25-60 m ahead, so that
# clip is longer and wider. Each clip is checked against its episode (collision-free, full length,
# scripted lane changes done); a clip that no longer plays its story fails test_use_case_plays_its_story.
# the paper's five use cases: (seconds, frame size); every one is rendered for each of SEEDS
USE_CASE_CLIPS = {
    "highway_lead_vehicle_brakes": (8, 320),
    "urban_pedestrian_crossing": (6, 320),
    "urban_left_turn_oncoming": (14, 320),  # a yielding ego waits for both oncoming cars: 10 s can end before its turn
    "urban_pull_back_in": (9, 320),
    "highway_onramp_insertion": (16, 400),
}
SEEDS = (0, 1)  # fixed in advance, never chosen by outcome
USE_CASES = {f"{name}_seed{seed}": (name, seed, seconds, size)
             for name, (seconds, size) in USE_CASE_CLIPS.items() for seed in SEEDS}


def _bank_file(name: str, *candidates: str) -> Optional[Path]:
    from scenario_bank import BANK_DIR

    for rel in candidates:
        path = Path(BANK_DIR) / rel.format(name=name)
        if path.is_file():
            return path
    return None


def _ground_truth(name: str) -> Elements:
    sidecar = _bank_file(name, "{name}/meta.json", "{name}.json")
    data = json.loads(sidecar.read_text(encoding="utf-8")) if sidecar else {}
    assert data.get("elements"), f"the sidecar of {name} has no ground-truth elements"
    return Elements.from_dict(data["elements"])


def _record_bank_episode(name: str, seed: int, path: Path, seconds: float, size: int) -> dict:
    """One episode of bank scenario ``name``, the ego driven by :class:`policies.CautiousDriver`, recorded to
    ``path`` (``size`` x ``size`` frames, the ego at the centre): the recording summary with the episode's
    collisions and trace (the clips of dv2s_gym/evalset are recorded so, by bench/evalsets/make_bev_clips.py)."""
    from envs.dv2s_env import DV2SEnv
    from envs.recording import record_episode
    from policies import CautiousDriver

    config = {"duration": float(seconds), "screen_width": int(size), "screen_height": int(size),
              "offscreen_rendering": True, "show_trajectories": False, "ego_policy": "agent"}
    env = DV2SEnv(scenario=name, config=config, render_mode="rgb_array")
    try:
        result = record_episode(env, path, CautiousDriver(env), seed=seed)
        return {"frames": result["frames"], "fps": env.config["policy_frequency"],
                "collisions": list(result["info"].get("collisions", [])), "trace": env.trace}
    finally:
        env.close()


def _episode_plays_its_story(name: str, summary: dict, expected_frames: int) -> Optional[str]:
    if summary["collisions"]:
        return f"the episode has a collision ({summary['collisions']})"
    if summary["frames"] < expected_frames:
        return f"the episode ended early ({summary['frames']} of {expected_frames} frames)"
    changes = [(tuple(e.get("actors", [])), e.get("direction")) for e in summary["trace"].events
               if e.get("kind") == "lane_change" and "ego" not in e.get("actors", [])]
    if name == "urban_pull_back_in" and {d for _, d in changes} != {"left", "right"}:
        return "the overtaker did not pull out and back in"
    if name == "highway_onramp_insertion" and "left" not in {d for _, d in changes}:
        return "the on-ramp car did not merge during the clip"
    return None


@pytest.fixture(scope="module")
def bank_clips(tmp_path_factory):
    videos = tmp_path_factory.mktemp("bank_videos")        # holds the .webm files only
    clips = {}
    for clip, (name, seed, seconds, size) in USE_CASES.items():
        path = videos / f"{clip}.webm"
        summary = _record_bank_episode(name, seed, path, seconds=seconds, size=size)
        problem = _episode_plays_its_story(name, summary, int(seconds * summary["fps"]) + 1)
        clips[clip] = (name, path, problem)
    return clips


@pytest.fixture(scope="module")
def bank_results(bank_clips):
    results = {}
    for clip_name in USE_CASES:
        name, path, problem = bank_clips[clip_name]
        # the analyzer sees a folder with videos only: no sidecar, no trace
        assert sorted(p.suffix for p in path.parent.iterdir()) == [".webm"] * len(USE_CASES)
        clip = read_video(path, fps=5.0, max_frames=100)
        analysis = analyze_bev(clip)
        truth = _ground_truth(name)
        results[clip_name] = {"problem": problem, "analysis": analysis,
                              "scs": scs(truth, analysis.elements), "hr": hallucination_rate(truth, analysis.elements),
                              "missing": sorted(element_set(truth) - element_set(analysis.elements)),
                              "extra": sorted(element_set(analysis.elements) - element_set(truth))}
    return results


@pytest.mark.slow
@pytest.mark.parametrize("clip_name", list(USE_CASES))
def test_use_case_plays_its_story(bank_results, clip_name):
    assert bank_results[clip_name]["problem"] is None, f"{clip_name}: {bank_results[clip_name]['problem']}"


# Known misses of the bev DRA on these fixed clips, recorded as strict xfails: the test fails the
# day they pass, so the entry must then be removed.
KNOWN_DRA_MISSES = {
    "highway_onramp_insertion_seed0": "the merging car is not detected on the ramp (SCS 0.25)",
    "highway_onramp_insertion_seed1": "the merging car is not detected on the ramp (SCS 0.25)",
    "urban_left_turn_oncoming_seed0": ("the second oncoming car, which gives way to the turning ego, is described as "
                                       "a car ahead on the ego's left, not as oncoming (HR 0.20)"),
    "urban_left_turn_oncoming_seed1": ("the second oncoming car, which gives way to the turning ego, is described as "
                                       "a car ahead on the ego's left, not as oncoming (HR 0.20)"),
}


def _scs_params():
    for clip_name in USE_CASES:
        marks = ([pytest.mark.xfail(reason=KNOWN_DRA_MISSES[clip_name], strict=True)]
                 if clip_name in KNOWN_DRA_MISSES else [])
        yield pytest.param(clip_name, marks=marks)


@pytest.mark.slow
@pytest.mark.parametrize("clip_name", list(_scs_params()))
def test_use_case_scs_and_hr(bank_results, clip_name):
    r = bank_results[clip_name]
    detail = f"{clip_name}: SCS {r['scs']:.2f} HR {r['hr']:.2f} missing {r['missing']} extra {r['extra']}"
    assert r["scs"] >= SCS_MIN, detail
    assert r["hr"] <= HR_MAX, detail


@pytest.mark.slow
def test_use_cases_aggregate(bank_results):
    assert np.mean([r["scs"] for r in bank_results.values()]) >= SCS_MIN
    assert np.mean([r["hr"] for r in bank_results.values()]) <= HR_MAX


@pytest.mark.slow
def test_use_case_descriptions_read_back(bank_results):
    from dv2s_gym.pipeline.semantics.text import elements_from_text

    for name, r in bank_results.items():
        a = r["analysis"]
        assert element_set(elements_from_text(a.description)) == element_set(a.elements), (name, a.description)


@pytest.mark.slow
def test_stock_highway_env(tmp_path):
    import gymnasium as gym
    import highway_env  # noqa: F401

    env = gym.make("highway-v0", render_mode="rgb_array",
                   config={"offscreen_rendering": True, "policy_frequency": 5, "duration": 5})
    path = tmp_path / "highway-v0.webm"
    try:
        env.reset(seed=0)
        with VideoWriter(path, fps=5) as video:
            video.write(env.render())
            for _ in range(20):
                *_, terminated, truncated, _info = env.step(1)
                video.write(env.render())
                if terminated or truncated:
                    break
    finally:
        env.close()
    result = analyze_bev_file(path)
    assert result.elements.road == "highway"
    assert "ego" in result.elements.participants and "car" in result.elements.participants


@pytest.mark.slow
def test_a_recorded_bank_episode_is_deterministic(tmp_path):
    decoded = []
    for k in range(2):
        path = tmp_path / f"run{k}.webm"
        summary = _record_bank_episode("highway_lead_vehicle_brakes", 3, path, seconds=2, size=160)
        assert summary["frames"] == 11 and path.is_file()
        decoded.append(read_video(path, fps=None, max_frames=100).frames)
    assert len(decoded[0]) == len(decoded[1])
    assert all(np.array_equal(a, b) for a, b in zip(*decoded))


# ----------------------------------------------------------------------------- a car ahead holding its speed (slow)
# Scenic scripts like the README's slow_car.scenic, driven with `dv2s run` (the rule driver, or the script's own
# behaviour for the ego that speeds up) for the command's default 20 s; the truth is the run's trace.
STEADY_LEAD_SCRIPT = """param map = 'highway_straight'
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 800)), with speed {ego}{ego_behavior}
lead = new Car following roadDirection from ego for {gap},
    with speed {car}, with behavior FollowLaneBehavior(target_speed={car})
"""
# name: (ego's speed, car's speed, gap, the ego's own target speed or None for the rule driver, seed,
#        whether the ego closes in on the car)
STEADY_LEAD_CASES = {
    "readme_slow_car": (25, 12, "Range(30, 50)", None, 1, True),   # the README's script and command
    "ego_brakes": (28, 15, 35, None, 2, True),
    "ego_speeds_up": (14, 24, 45, 24, 1, False),
    "ego_keeps_its_speed": (22, 22, 40, None, 3, False),
}


@pytest.fixture(scope="module")
def steady_lead_runs(tmp_path_factory):
    import contextlib
    import gzip
    import io

    from dv2s_gym.cli import main

    folder = tmp_path_factory.mktemp("steady_lead")
    runs = {}
    for name, (ego, car, gap, target, seed, closes_in) in STEADY_LEAD_CASES.items():
        behavior = f",\n    with behavior FollowLaneBehavior(target_speed={target})" if target else ""
        script = folder / f"{name}.scenic"
        script.write_text(STEADY_LEAD_SCRIPT.format(ego=ego, car=car, gap=gap, ego_behavior=behavior))
        video, trace = folder / f"{name}.webm", folder / f"{name}.json.gz"
        argv = ["run", str(script), "--video", str(video), "--seed", str(seed), "--trace", str(trace)]
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(argv + (["--ego-policy", "scenic"] if target else [])) == 0
        with gzip.open(trace, "rt") as fh:
            recorded = json.load(fh)
        states = recorded["states"]                       # states[i][actor] = [x, y, heading, speed]
        other = next(actor for actor in recorded["kinds"] if actor != "ego")
        truth_ego = np.array([s["ego"][3] for s in states])
        truth_car = np.array([s[other][3] for s in states if other in s])
        assert np.ptp(truth_car) < 0.5   # the car holds its speed: the premise of these clips
        runs[name] = (analyze_bev_file(video), truth_ego, float(truth_car[0]), closes_in)
    return runs


@pytest.mark.slow
@pytest.mark.parametrize("name", list(STEADY_LEAD_CASES))
def test_steady_car_ahead_holds_its_speed(steady_lead_runs, name):
    result, truth_ego, truth_car, closes_in = steady_lead_runs[name]
    lead = max(result.tracks, key=lambda trk: len(trk["frames"]))
    car = np.array([np.nan if s is None else s for s in lead["speed"]], float)
    measured = np.array([np.nan if s is None else s for s in result.debug["ego_speed"]], float)
    scale = float(np.nanmedian(car)) / truth_car      # the measured scale's error, common to every speed
    assert 0.8 < scale < 1.2, (scale, result.description)
    n = min(len(measured), len(truth_ego))
    # a wrong alias of the dashed lines is 21.65 m/s off at 5 frames/s; a frame or two of lag is ~1.5 m/s
    assert np.nanmax(np.abs(measured[:n] / scale - truth_ego[:n])) < 3.0, np.round(measured[:n] / scale, 1)
    assert (np.nanmax(car) - np.nanmin(car)) / np.nanmedian(car) < 0.15, np.round(car, 1)
    e = result.elements
    assert not {a for k, a in e.actions if k == "car"} & {"brake", "stop", "accelerate"}, result.description
    if closes_in:
        assert ("car", "keep_lane") in e.actions and ("car", "ahead_of", "ego") in e.relations and \
            ("car", "same_lane", "ego") in e.relations, result.description
        assert "a slower car ahead of it in the same lane keeps to its lane" in result.description
