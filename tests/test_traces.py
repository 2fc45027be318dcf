"""Episode traces: save, load, exact replay, tamper detection and corrupt files."""

from __future__ import annotations

import copy
import gzip
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from envs.dv2s_env import DV2SEnv  # noqa: E402
from envs.replay import replay_trace  # noqa: E402
from envs.trace import TRACE_VERSION, EpisodeTrace, TraceMismatchError  # noqa: E402
from scenario_bank import BANK_DIR  # noqa: E402
from scenario_bank.maps import MAPS_DIR  # noqa: E402

BRAKES = "highway_lead_vehicle_brakes"
PULL_BACK_IN = "urban_pull_back_in"
FASTER = 3


def run_episode(scenario, seed, policy, **config):
    config.setdefault("duration", 3.0)
    env = DV2SEnv(scenario=scenario, config=config)
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed)
    while True:
        obs, _, terminated, truncated, info = env.step(policy(env))
        if terminated or truncated:
            return env, info


@pytest.fixture(scope="module")
def discrete_episode(tmp_path_factory):
    """An episode with random lane changes and speed changes, saved both ways."""
    env, _ = run_episode(PULL_BACK_IN, 5, lambda e: e.action_space.sample())
    folder = tmp_path_factory.mktemp("traces")
    paths = {kind: env.save_trace(folder / f"episode.{kind}") for kind in ("json", "json.gz")}
    yield env, paths
    env.close()


@pytest.fixture(scope="module")
def crash_episode(tmp_path_factory):
    """An episode that ends in a collision (so its events hold one)."""
    for seed in range(10):
        env, info = run_episode(BRAKES, seed, lambda e: FASTER, duration=10.0)
        if info["collisions"]:
            path = env.save_trace(tmp_path_factory.mktemp("crash") / "crash.json")
            yield env, path
            env.close()
            return
        env.close()
    pytest.fail("no crash found")


def test_trace_records_the_episode(discrete_episode):
    env, paths = discrete_episode
    trace = EpisodeTrace.load(paths["json"])
    assert trace.scenario == PULL_BACK_IN
    assert trace.source == (BANK_DIR / PULL_BACK_IN / "scenario.scenic").read_text()
    assert trace.seed == 5 and trace.scene_seed == env.trace.scene_seed
    assert trace.params["map"].endswith("highway_straight.xodr")
    assert trace.config["duration"] == 3.0
    assert len(trace.states) == len(trace.actions) + 1 >= 5
    assert len(trace.actions) == round(env.time * env.config["policy_frequency"])
    assert all("ego" in states for states in trace.states)
    assert all(len(state) == 4 for states in trace.states for state in states.values())
    assert trace.version == TRACE_VERSION


@pytest.mark.parametrize("kind", ["json", "json.gz"])
def test_replay_reproduces_every_state(discrete_episode, kind):
    env, paths = discrete_episode
    if kind == "json.gz":
        assert paths[kind].read_bytes()[:2] == b"\x1f\x8b"  # really compressed
        assert paths[kind].stat().st_size < paths["json"].stat().st_size
    trace = EpisodeTrace.load(paths[kind])
    assert trace == env.trace
    replay_env, replayed = replay_trace(trace)
    assert replayed.states == trace.states
    assert replayed.events == trace.events
    assert replayed.actions == trace.actions
    assert replayed.scenario == trace.scenario
    replay_env.close()


def test_replay_of_a_crash(crash_episode):
    env, path = crash_episode
    trace = EpisodeTrace.load(path)
    assert any(e["kind"] == "collision" and "ego" in e["actors"] for e in trace.events)
    replay_env, replayed = replay_trace(trace)
    assert replayed.events == trace.events
    assert replayed.states == trace.states
    assert replay_env.vehicle.crashed
    replay_env.close()


def test_replay_of_continuous_actions(tmp_path):
    env, _ = run_episode(BRAKES, 2, lambda e: e.action_space.sample(),
                         duration=1.0, action={"type": "ContinuousAction"})
    path = env.save_trace(tmp_path / "continuous.json.gz")
    env.close()
    trace = EpisodeTrace.load(path)
    assert all(isinstance(a, list) and len(a) == 2 for a in trace.actions)
    replay_env, replayed = replay_trace(trace)
    assert replayed.states == trace.states
    replay_env.close()


def test_replay_of_an_unseeded_episode(tmp_path):
    env = DV2SEnv(scenario=BRAKES, config={"duration": 1.0})
    env.reset()
    for _ in range(5):
        env.step(FASTER)
    trace = EpisodeTrace.load(env.save_trace(tmp_path / "unseeded.json"))
    env.close()
    assert trace.seed is None
    replay_env, replayed = replay_trace(trace)
    assert replayed.states == trace.states
    replay_env.close()


@pytest.mark.slow
def test_replay_of_a_script_with_a_local_map(tmp_path, monkeypatch):
    """`localPath` maps resolve as in the original run, from any working directory."""
    folder = tmp_path / "my_scenario"
    folder.mkdir()
    shutil.copy(MAPS_DIR / "highway_straight.xodr", folder / "road.xodr")
    script = folder / "follow.scenic"
    script.write_text(
        "param map = localPath('road.xodr')\n"
        "model scenic.domains.driving.model\n"
        "ego = new Car with speed 10\n"
        "lead = new Car following roadDirection from ego for 20,\n"
        "    with behavior FollowLaneBehavior(target_speed=5)\n"
    )
    env, _ = run_episode(str(script), 0, lambda e: FASTER, duration=1.0)
    path = env.save_trace(tmp_path / "local.json")
    env.close()
    monkeypatch.chdir(tmp_path)
    trace = EpisodeTrace.load(path)
    replay_env, replayed = replay_trace(trace)
    assert replayed.states == trace.states and replayed.scenario == "follow"
    replay_env.close()
    script.unlink()  # only the source text in the trace is left
    replay_env, replayed = replay_trace(trace)
    assert replayed.states == trace.states
    replay_env.close()


def test_tampered_state_is_detected(discrete_episode):
    _, paths = discrete_episode
    trace = EpisodeTrace.load(paths["json"])
    trace.states[7]["ego"][0] += 1e-9
    with pytest.raises(TraceMismatchError, match="diverged at step 7"):
        replay_trace(trace)
    _, replayed = replay_trace(trace, check=False)  # without checking it replays to the end
    assert len(replayed.states) == len(trace.states)


def test_tampered_action_is_detected(discrete_episode):
    _, paths = discrete_episode
    trace = EpisodeTrace.load(paths["json"])
    trace.actions[2] = 0 if trace.actions[2] != 0 else 2
    with pytest.raises(TraceMismatchError):
        replay_trace(trace)


def test_tampered_scene_is_detected(discrete_episode):
    _, paths = discrete_episode
    trace = copy.deepcopy(EpisodeTrace.load(paths["json"]))
    trace.scene_seed += 1
    with pytest.raises(TraceMismatchError, match="diverged at step 0"):
        replay_trace(trace)


def test_save_is_atomic_and_needs_an_episode(tmp_path, discrete_episode):
    env, _ = discrete_episode
    target = tmp_path / "nested" / "t.json"
    env.save_trace(target)
    assert json.loads(target.read_text())["scenario"] == PULL_BACK_IN
    assert sorted(p.name for p in target.parent.iterdir()) == ["t.json"]  # no temporary left
    fresh = DV2SEnv.__new__(DV2SEnv)
    fresh._trace = None
    with pytest.raises(RuntimeError, match="reset"):
        fresh.save_trace(tmp_path / "none.json")


@pytest.mark.parametrize(
    "name, content",
    [
        ("bad.json", b"{not json"),
        ("empty.json", b""),
        ("binary.json", bytes(range(256))),
        ("bad.json.gz", b"\x1f\x8b\x08garbage"),
        ("list.json", b"[1, 2, 3]"),
        ("other.json", b'{"foo": 1}'),
    ],
)
def test_corrupt_trace_file_gives_a_clear_error(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError, match="is not a dv2s episode trace") as info:
        EpisodeTrace.load(path)
    assert str(path) in str(info.value)


def test_truncated_gzip_trace(tmp_path, discrete_episode):
    _, paths = discrete_episode
    path = tmp_path / "cut.json.gz"
    path.write_bytes(paths["json.gz"].read_bytes()[:200])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        EpisodeTrace.load(path)


def test_trace_from_a_newer_version(tmp_path, discrete_episode):
    _, paths = discrete_episode
    data = json.loads(paths["json"].read_text())
    data["version"] = TRACE_VERSION + 1
    path = tmp_path / "future.json.gz"
    path.write_bytes(gzip.compress(json.dumps(data).encode()))
    with pytest.raises(ValueError, match="newer dv2s-gym"):
        EpisodeTrace.load(path)


@pytest.mark.slow
def test_a_compressed_trace_is_read_with_a_size_cap(tmp_path):
    # 1 MB of gzip that would become 1 GiB of text
    path = tmp_path / "bomb.json.gz"
    with gzip.open(path, "wb", compresslevel=9) as handle:
        handle.write(b'{"version": 1, "pad": "')
        chunk = b" " * 2**20
        for _ in range(1024):
            handle.write(chunk)
        handle.write(b'"}')
    assert path.stat().st_size < 4 * 2**20
    with pytest.raises(ValueError, match="MiB .uncompressed. is refused"):
        EpisodeTrace.load(path)


@pytest.mark.parametrize("change", [{"simulation_frequency": 1e9}, {"policy_frequency": 0},
                                    {"duration": float("inf")}, {"simulation_frequency": "15"}])
def test_a_trace_cannot_set_how_the_replay_runs(tmp_path, discrete_episode, change):
    """A trace file is data from anywhere: a shipped script with a config that would run for ever is refused."""
    _, paths = discrete_episode
    trace = EpisodeTrace.load(paths["json"])
    trace.config.update(change)
    with pytest.raises(ValueError, match="the trace's config has"):
        replay_trace(trace)


def test_a_trace_does_not_choose_the_step_time_limit(discrete_episode):
    from envs.replay import trace_config

    _, paths = discrete_episode
    trace = EpisodeTrace.load(paths["json"])
    trace.config["step_time_limit"] = None
    assert "step_time_limit" not in trace_config(trace)


def test_missing_trace_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        EpisodeTrace.load(tmp_path / "absent.json")


def test_states_round_trip_exactly(discrete_episode):
    env, paths = discrete_episode
    loaded = EpisodeTrace.load(paths["json.gz"])
    for original, reloaded in zip(env.trace.states, loaded.states):
        for name, state in original.items():
            assert np.array_equal(np.array(state), np.array(reloaded[name]))


def test_a_trace_file_replays_into_a_video_of_every_step(discrete_episode, tmp_path):
    import cv2

    from envs.replay import replay_trace_file

    env, paths = discrete_episode
    video = tmp_path / "replay.webm"
    trace, replayed = replay_trace_file(paths["json.gz"], video=video)
    assert trace == env.trace and replayed.states == trace.states
    capture, frames = cv2.VideoCapture(str(video)), 0
    while capture.read()[0]:
        frames += 1
    capture.release()
    assert frames == len(trace.actions) + 1  # the reset, then every step
