"""A run folder whose record is of another format than this dv2s-gym writes (or of none) is refused in one line
naming the folder, what it holds and the fix (start a new ``--out`` folder), for every resumable run kind; a folder
this dv2s-gym wrote resumes. No older layout is read on."""

from __future__ import annotations

import json

import pytest

from mining_helpers import SpaceBuilt, recorded_run_folder
from loop_helpers import run_loop
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.loop.state import STATE_VERSION
from dv2s_gym.loop.settings import LoopError
from dv2s_gym.mining.miner import SETTINGS_VERSION, mine
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.regress.errors import ReportMismatchError, ResumeMismatchError
from dv2s_gym.regress.report import SCHEMA, SCHEMA_VERSION, load_report
from dv2s_gym.regress.store import RunStore
from policies.dagger_checkpoint import CHECKPOINT_DIR, DAggerCheckpoint, DAggerResumeError
from policies.run_identity import code_identity
from policies.training import TrainConfig, TrainingError, run_settings, train
from scenario_bank.bank import Bank
from scenario_bank.run_identity import bank_identity

SCENARIOS = ("highway_lead_vehicle_brakes",)

_ERRORED = {"episodes": 1, "scenarios": {"s": 1}, "messages": {"s": [{"message": "boom", "count": 1}]},
            "examples": {"s": "boom"}}


def _refusal(folder, what: str, file: str, found: str, reads: int) -> str:
    return (f"{folder} holds {what} written by another version of dv2s-gym (its {file} records {found}, this "
            f"dv2s-gym reads format {reads}); start a new --out folder")



@pytest.fixture
def mining_folder(tmp_path, monkeypatch):
    """A mining run folder whose settings.json a seed-0 run wrote; building a scene space raises
    :class:`SpaceBuilt` (the resume checks are behind it)."""
    return recorded_run_folder(tmp_path / "mine", SCENARIOS, monkeypatch)


def _mine(out):
    mine("rule", MineSettings(budget=2, scenarios=SCENARIOS, seed=0), out=out, progress=False, reports=False)


@pytest.mark.parametrize("change, found", [({"version": SETTINGS_VERSION - 1}, f"format {SETTINGS_VERSION - 1}"),
                                           ({"version": None}, "no format"), ({"schema": None}, "no format")])
def test_a_mining_folder_of_another_format_is_refused_and_one_of_this_format_resumes(mining_folder, change, found):
    with pytest.raises(SpaceBuilt):  # past the resume checks
        _mine(mining_folder)
    path = mining_folder / "settings.json"
    path.write_text(json.dumps({**json.loads(path.read_text(encoding="utf-8")), **change}), encoding="utf-8")
    with pytest.raises(MiningError) as error:
        _mine(mining_folder)
    assert str(error.value) == _refusal(mining_folder, "a mining run", "settings.json", found, SETTINGS_VERSION)


@pytest.mark.parametrize("record", [
    {"settings": {"holdout_by": "family"}, "start": None, "rounds": []},
    {"schema": "dv2s-loop-state", "version": 0, "settings": {}, "start": None, "rounds": []},
    {"schema": "dv2s-loop-state", "version": 1, "settings": {}, "start": None, "rounds": []},  # absolute paths
    {"schema": "dv2s-loop-state", "settings": {"holdout_by": "family"}, "start": None,
     "rounds": [{"round": 1, "steps": {"mine": {"errored": _ERRORED}}, "timings": {}}]},
])
def test_a_loop_folder_of_another_format_is_refused_in_one_line(tmp_path, record):
    folder = tmp_path / "loop"
    folder.mkdir()
    (folder / "loop.json").write_text(json.dumps(record))
    with pytest.raises(LoopError) as error:
        run_loop("dv2s-ppo", out=folder, budget=8, log=lambda _: None, progress=False)
    found = f"format {record['version']}" if "version" in record else "no format"
    assert str(error.value) == _refusal(folder, "a loop", "loop.json", found, STATE_VERSION)


class _PastTheCheck(Exception):
    pass


def _past_the_check(line: str) -> None:
    if "holds no checkpoint yet" in line:  # past the resume checks (the run had not reached its first checkpoint)
        raise _PastTheCheck()


def test_a_training_folder_of_another_format_is_refused_and_one_of_this_format_resumes(tmp_path):
    """A resumed run with unchanged settings resumes: its fine-tuning settings, ``None`` and left out of
    ``run.json``, are ``None`` on both sides."""
    out = tmp_path / "run"
    out.mkdir()
    config = TrainConfig(out=str(out), algo="ppo", scenarios=SCENARIOS, steps=300, n_envs=1, eval_freq=0,
                         card_seeds=0, checkpoint_freq=0, progress_bar=False, vec_env="dummy")
    assert "learning_rate" not in config.to_json()
    path = out / "run.json"
    path.write_text(json.dumps({"schema": "dv2s-train-run", "version": 2, "config": config.to_json(),
                                "bank_identity": bank_identity(Bank(), SCENARIOS), "code_identity": code_identity(),
                                "segments": []}), encoding="utf-8")
    with pytest.raises(_PastTheCheck):
        train(run_settings(out, {}, resume=True), resume=True, log=_past_the_check)
    for record, found in (({"config": config.to_json(), "segments": []}, "no format"),
                          ({"schema": "dv2s-train-run", "version": 0, "config": config.to_json(), "segments": []},
                           "format 0")):
        path.write_text(json.dumps(record), encoding="utf-8")
        with pytest.raises(TrainingError) as error:
            run_settings(out, {}, resume=True)
        assert str(error.value) == _refusal(out, "a training run", "run.json", found, 2)


_PROGRESS = {"schema": "dv2s-dagger-checkpoint", "identity": {"seed": 0}, "iteration": 0, "history": [], "rng": {},
             "envs": [], "partial": None}


@pytest.mark.parametrize("format_keys, found", [({"schema_version": 1}, "no format"), ({"version": 1}, "format 1"),
                                                ({"version": 2}, "format 2"), ({"version": 3}, None)])
def test_a_dagger_checkpoint_of_another_format_is_refused(tmp_path, format_keys, found):
    folder = tmp_path / CHECKPOINT_DIR
    folder.mkdir()
    (folder / "progress.json").write_text(json.dumps({**_PROGRESS, **format_keys}))
    checkpoint = DAggerCheckpoint(folder, {"seed": 0})
    if found is None:  # this format: the settings are compared, and match
        assert checkpoint.load().iteration == 0
        return
    with pytest.raises(DAggerResumeError) as error:
        checkpoint.load()
    assert str(error.value) == _refusal(folder, "the checkpoint of an unfinished DAgger run", "progress.json", found, 3)


@pytest.mark.parametrize("format_keys, found", [({"version": 3}, "format 3"), ({}, "no format")])
def test_a_regression_folder_of_another_format_is_refused_and_one_of_this_format_resumes(tmp_path, format_keys,
                                                                                          found):
    settings = {"episodes": 4, "seed": 0, "scenarios": ["a"]}
    with RunStore(tmp_path, settings) as store:
        assert store.open() == {}
    with RunStore(tmp_path, settings) as store:
        assert store.open() == {}  # this format, the same settings: resumed
    path = tmp_path / "run.json"
    record = {key: value for key, value in json.loads(path.read_text()).items() if key != "version"}
    path.write_text(json.dumps({**record, **format_keys}))
    with pytest.raises(ResumeMismatchError) as error, RunStore(tmp_path, settings) as store:
        store.open()
    assert str(error.value) == _refusal(tmp_path, "a regression run", "run.json", found, 4)


def test_a_regress_report_of_another_schema_version_is_refused(tmp_path):
    path = tmp_path / "report.json"
    path.write_text(json.dumps({"schema": SCHEMA, "schema_version": SCHEMA_VERSION - 1,
                                "settings": {"seed": 0, "episodes": 2}}))
    with pytest.raises(ReportMismatchError) as error:
        load_report(path)
    message = str(error.value)
    assert "\n" not in message and str(path) in message
    assert f"has schema version {SCHEMA_VERSION - 1}, this dv2s-gym reads version {SCHEMA_VERSION}" in message


def test_the_older_paths_are_gone():
    """No split by cluster, no failure kinds assumed for a report that names none, no anonymous error counts, no
    defaults for settings a record lacks, no family made up for a record without one."""
    from dv2s_gym.loop import errored
    from dv2s_gym.loop.record import ErroredEpisodes
    from dv2s_gym.loop import split
    from dv2s_gym.mining.family import record_family
    from dv2s_gym.regress import failures
    from scenario_bank import run_identity
    from scenario_bank.failure_types import FailureType
    from scenario_bank.records import EpisodeRecord

    assert not hasattr(split, "split_by_cluster") and not hasattr(failures, "FAILURE_BEFORE_CHOICE")
    assert not hasattr(run_identity, "setting_defaults")
    assert "counted_before_choice" not in FailureType.__dataclass_fields__
    merged = errored.merged_messages([ErroredEpisodes.from_dict(_ERRORED)] * 2)
    assert merged == {"s": [{"message": "boom", "count": 2}]}
    with pytest.raises(MiningError, match="episode 3 of s records no scenario family"):
        record_family(EpisodeRecord(index=3, scenario="s", seed=0))
