"""A run's settings are listed once, on their dataclass: which fields are its resume identity, how a run folder
records them, and which ``dv2s loop`` options carry a setting's own name are read from the fields."""

from __future__ import annotations

import dataclasses
import json

from dv2s_gym.cli import build_parser
from dv2s_gym.cli.loop import _VALUED, loop_settings
from dv2s_gym.mining import miner
from dv2s_gym.loop import state
from dv2s_gym.loop.settings import LoopSettings
from dv2s_gym.mining.monitors import MonitorSettings
from dv2s_gym.mining.settings import MineSettings

NOT_RECORDED_BY_MINE = {"convert", "conversion", "max_conversions"}


def _names(cls) -> set:
    return {field.name for field in dataclasses.fields(cls)}


def test_loop_identity_is_every_setting_but_rounds_and_workers():
    assert set(state.IDENTITY) == {"policy"} | _names(LoopSettings) - {"rounds", "workers"}


def test_mine_identity_is_every_recorded_setting_but_budget():
    assert set(miner._RESUME_KEYS) == {"policy"} | _names(MineSettings) - NOT_RECORDED_BY_MINE - {"budget"}


def test_loop_record_is_json_of_every_setting(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    settings = LoopSettings.evidence(bank_dir="bank", scenarios=("a", "b"), margin=0, holdout_fraction=1,
                                     mined_share=0.25, fine_tune_lr=1)
    recorded = settings.recorded()
    assert set(recorded) == _names(LoopSettings)
    assert json.loads(json.dumps(recorded)) == recorded
    assert recorded["bank_dir"] == str(tmp_path.resolve() / "bank")
    assert recorded["scenarios"] == ["a", "b"]
    # a float setting is recorded as a float; an optional one as given
    assert json.dumps(recorded["margin"]) == "0.0" and json.dumps(recorded["holdout_fraction"]) == "1.0"
    assert json.dumps(recorded["fine_tune_lr"]) == "1"
    assert recorded["budget"] == 240 and recorded["fine_tune_reward"] == {"standing": -0.3}


def test_mine_record_leaves_out_what_a_resume_may_change():
    settings = MineSettings(sampler_options={}, scenarios=("x",), env_config={"duration": 5}, ttc_threshold=2,
                            convert=True, bank_dir="bank", max_conversions=3)
    recorded = settings.recorded()
    assert set(recorded) == _names(MineSettings) - NOT_RECORDED_BY_MINE
    assert recorded["sampler_options"] is None  # no options recorded as none
    assert recorded["scenarios"] == ["x"] and recorded["env_config"] == {"duration": 5}
    assert json.dumps(recorded["ttc_threshold"]) == "2.0"
    assert MineSettings(sampler_options={"alpha": 0.9}).recorded()["sampler_options"] == {"alpha": 0.9}


def test_loop_options_named_like_their_setting_reach_the_settings():
    args = build_parser().parse_args(["loop"])
    for name in _VALUED:
        assert hasattr(args, name), name
    given = build_parser().parse_args(["loop", "--rounds", "3", "--k-eval", "7", "--seed", "5", "--workers", "1"])
    settings = loop_settings(given)
    assert (settings.rounds, settings.k_eval, settings.seed, settings.workers) == (3, 7, 5, 1)


def test_a_run_folder_s_settings_are_read_in_one_place(tmp_path):
    import pytest

    from dv2s_gym.mining.errors import MiningError
    from dv2s_gym.mining.report import MiningReportError
    from dv2s_gym.mining.settings import read_run_settings

    assert read_run_settings(tmp_path) is None
    values = {"policy": "rule", "bank_dir": "/b", "env_config": {"duration": 5}, "ttc_threshold": 1.5,
              "stall_seconds": None, "scenarios": ["a"]}
    (tmp_path / "settings.json").write_text(json.dumps(values))
    settings = read_run_settings(tmp_path)
    assert dict(settings.values) == values
    with pytest.raises(TypeError):
        settings.values["policy"] = "other"  # read-only: the run's record, not a scratch dict
    assert (settings.scenarios, settings.batch, settings.sampler) == (["a"], None, None)
    assert (settings.policy, settings.bank_dir, settings.env_config) == ("rule", "/b", {"duration": 5})
    assert settings.monitor == MonitorSettings(ttc_threshold=1.5)  # an absent or null monitor setting: the default
    assert settings.path == tmp_path / "settings.json"
    for content, needle in (("{garbage", "is not readable JSON"), ("[1]", "is not a mining run's settings")):
        (tmp_path / "settings.json").write_text(content)
        with pytest.raises(MiningError, match=needle):
            read_run_settings(tmp_path)
        with pytest.raises(MiningReportError, match=needle):
            read_run_settings(tmp_path, error=MiningReportError)
