"""A failure mined in a scenario the package does not ship (a user's own, run in the jail): its failure video and
its exact replay are made as for a shipped scenario, and the exact replay is kept even when the video fails."""

from __future__ import annotations

import pytest

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.convert import convert_failure
from dv2s_gym.mining.conversion.exact_replay import replay_failure
from dv2s_gym.mining.monitors import MonitorSettings
from dv2s_gym.pipeline.video import read_video
from envs.dv2s_env import DV2SEnv
from scenario_bank.bank import Bank, Sidecar

KEEP_LANE = ConversionSettings(policy="keep_lane")
"""The conversion settings of the tests: the deterministic policy that fails."""

STOPPED_VAN = '''"""A van stands still in the ego's lane on a straight highway."""
param map = 'highway_straight'
model scenic.domains.driving.model

param ego_speed = Range(18, 28)
param van_gap = Range(40, 90)

egoLane = Uniform(*network.lanes)
ego = new Car at egoLane.centerline.pointAlongBy(Range(80, 900)),
    with speed globalParameters.ego_speed
van = new Car following roadDirection from ego for globalParameters.van_gap,
    with name "van", with speed 0
'''
NAME = "user_stopped_van"


@pytest.fixture(scope="module")
def user_bank(tmp_path_factory):
    folder = tmp_path_factory.mktemp("user") / "bank"
    Bank(folder).add(STOPPED_VAN, Sidecar(description="A van stands still in the ego's lane.", name=NAME,
                                          tags=["user"]))
    return folder


@pytest.fixture(scope="module")
def record(user_bank) -> dict:
    from dv2s_gym.mining.tasks import MineTask, run_mine_task

    env = DV2SEnv(scenario=NAME, bank_dir=str(user_bank))
    try:
        assert env.unwrapped.runs_in_jail  # a user's scenario: simulated in the jail
    finally:
        env.close()
    record = run_mine_task(MineTask(index=0, policy="keep_lane", scenario=NAME, seed=3,
                                    params={"ego_speed": 23.0, "van_gap": 60.0}, bank_dir=str(user_bank),
                                    monitor=MonitorSettings(ttc_threshold=1.0, stall_seconds=5.0)).to_json()).to_dict()
    assert record["error"] is None and record["failure"]["type"] == "collision", record
    return record


@pytest.mark.slow
def test_a_failure_in_a_jailed_scenario_gets_its_video_and_its_exact_replay(record, user_bank, tmp_path, monkeypatch):
    from dv2s_gym.pipeline import stages

    def no_description(*args, **kwargs):  # the stages after the replay are not what this test is about
        raise RuntimeError("describing is not part of this test")

    monkeypatch.setattr(stages, "describe", no_description)
    out = convert_failure(record, tmp_path / "run", KEEP_LANE.replace(k=2, before=1.0, after=1.0), bank=user_bank)
    assert out.to_dict()["stage"] == "describe", out  # past the video and the replay
    assert out.to_dict()["timings"].keys() >= {"video", "interaction", "replay"}
    clip = read_video(tmp_path / "run" / out.to_dict()["video"], fps=None, max_frames=1000, max_pixels=10**7)
    k = record["failure"]["step"]
    assert k + 5 > record["result"]["steps"]  # the last second was driven past the episode's end, in the jail
    assert len(clip.frames) == 11  # 1 s before, the failure's frame, 1 s after at 5 frames per second
    rerun = replay_failure(user_bank, out.to_dict()["replay_entry"])
    assert rerun["matches"] and rerun["failure"]["type"] == "collision"


@pytest.mark.slow
def test_the_exact_replay_is_kept_when_the_video_stage_fails(record, user_bank, tmp_path, monkeypatch):
    from dv2s_gym.mining.conversion import convert as convert_module

    def broken(*args, **kwargs):
        raise OSError("no space left on device")

    monkeypatch.setattr(convert_module, "write_failure_video", broken)  # where convert calls it
    bank = tmp_path / "bank"
    Bank(bank).add(STOPPED_VAN, Sidecar(description="A van stands still in the ego's lane.", name=NAME))
    out = convert_failure(record, tmp_path / "run", KEEP_LANE.replace(k=2), bank=bank)
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "video"
    assert out.to_dict()["reason"] == "video: OSError: no space left on device" and out.to_dict()["rejections"] == [out.to_dict()["reason"]]
    assert out.to_dict()["video"] is None and out.to_dict()["replay_entry"] is not None
    entry = Bank(bank).get(out.to_dict()["replay_entry"])
    source = entry.source.to_dict()
    assert source["converted_rejections"] == [out.to_dict()["reason"]]
    assert source["video"] is None and source["trace"] == "trace.json.gz"
    assert replay_failure(bank, out.to_dict()["replay_entry"])["matches"]
    # a replay that fails as well is recorded beside the video's reason
    diverged = convert_failure({**record, "result": {**record["result"], "trajectory_hash": "0" * 64}},
                               tmp_path / "run2", KEEP_LANE.replace(k=2), bank=bank)
    assert diverged.to_dict()["stage"] == "video" and diverged.to_dict()["replay_entry"] is None
    assert [r.split(":")[0] for r in diverged.to_dict()["rejections"]] == ["video", "replay"]
    assert "does not replay the failing episode" in diverged.to_dict()["rejections"][1]
