"""``dv2s loop`` records the user's files its code read in ``loop.json`` (those of its own process, of its held-out
pools' workers, and those its mining and regression runs recorded), and a resume checks them: a plug-in's data
file edited between two runs of the loop is refused naming it, so one round is never judged by two detectors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dv2s_gym.loop.heldout import HeldOutStore
from dv2s_gym.loop.settings import LoopError, LoopSettings
from dv2s_gym.loop.state import HOLDOUT_BY, LoopState
from policies.run_identity import CODE_IDENTITY, RESUME_FINGERPRINT, resume_fingerprint
from scenario_bank.atomic import file_sha256
from scenario_bank.read_files import ReadFile
from scenario_bank.records import HeldOutEpisode
from test_read_identity import LIMITS_PLUGIN

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "highway_lead_vehicle_brakes"


def _settings():
    return {"policy": "dv2s-ppo", **LoopSettings().recorded(), "workers": 1, "holdout_by": HOLDOUT_BY,
            "env_config": {}, "fine_tune_env_config": {}, RESUME_FINGERPRINT: resume_fingerprint("dv2s-ppo")}


def _state(folder: Path) -> LoopState:
    return LoopState(folder / "loop.json", _settings())


def test_a_file_a_held_out_worker_read_is_recorded_before_its_episode_and_checked_on_resume(tmp_path):
    data = tmp_path / "data" / "limits.json"
    data.parent.mkdir()
    data.write_text('{"speed": 20.0}', encoding="utf-8")
    state = _state(tmp_path / "loop")
    state.save()
    seen = []

    def record(reads):
        seen.append(store.path.is_file())  # the episode is not saved yet
        state.record_reads(reads)

    store = HeldOutStore(tmp_path / "loop" / "round_1" / "heldout.jsonl", on_reads=record)
    store.append(HeldOutEpisode(role="before", scenario=SCENARIO, seed=1, policy="dv2s-ppo", error="did not run"),
                 reads=[ReadFile(str(data.resolve()), None, file_sha256(data))])
    key = f"user file {data.resolve()} (SHA-256)"
    assert seen == [False]  # given before the episode was saved, and written
    assert json.loads(state.path.read_text())[CODE_IDENTITY][key] == file_sha256(data)
    assert len(store.path.read_text().splitlines()) == 1
    _state(tmp_path / "loop")  # unchanged: resumes
    before = file_sha256(data)
    data.write_text('{"speed": 1000.0}', encoding="utf-8")
    with pytest.raises(LoopError) as error:
        _state(tmp_path / "loop")
    message = str(error.value)
    assert f"{tmp_path / 'loop'} holds a loop made with other code (files the code read differ: " in message
    assert f"{key}: run has {before[:12]}, now {file_sha256(data)[:12]}" in message


def test_a_finished_steps_run_record_gives_its_files_to_loop_json(tmp_path):
    state = _state(tmp_path / "loop")
    mine = tmp_path / "loop" / "round_1" / "mine" / "settings.json"
    mine.parent.mkdir(parents=True)
    facts = {"user file limits.json (SHA-256)": "a" * 64, "dv2s sources (SHA-256)": "b" * 64}
    mine.write_text(json.dumps({CODE_IDENTITY: facts}), encoding="utf-8")
    regress = tmp_path / "loop" / "round_1" / "regress" / "run.json"
    regress.parent.mkdir(parents=True)
    regress.write_text(json.dumps({"settings": {CODE_IDENTITY: {"user module speedhelp (SHA-256)": "c" * 64}}}),
                       encoding="utf-8")
    assert state.add_reads(records=[mine, regress, tmp_path / "none.json"])
    identity = state.extra[CODE_IDENTITY]
    assert identity["user file limits.json (SHA-256)"] == "a" * 64
    assert identity["user module speedhelp (SHA-256)"] == "c" * 64
    assert identity["dv2s sources (SHA-256)"] != "b" * 64  # the loop's own, not the run's
    assert not state.add_reads(records=[mine, regress])  # nothing new the second time


def _loop(base: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DV2S_PLUGINS": "myfail",
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(base)])}
    # one round whose mining keeps nothing (no conversion, no replay): the loop ends after mining
    return subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "loop", "--policy", "dv2s-ppo", "--scenarios", SCENARIO,
                           "--budget", "2", "--max-conversions", "0", "--max-replays", "0", "--rounds", "1",
                           "--untouched-seeds", "0", "--workers", "2", "--no-progress", "--out", "loop"],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
def test_a_loop_resumed_after_its_detectors_data_file_changed_is_refused_naming_it(tmp_path):
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    (plugins / "myfail.py").write_text(LIMITS_PLUGIN, encoding="utf-8")
    limits = plugins / "limits.json"
    limits.write_text('{"speed": 20.0}', encoding="utf-8")
    first = _loop(plugins, tmp_path)
    finished = (0, 1, 3)  # the loop's verdicts; 2 is a refusal
    assert first.returncode in finished and "no mined scenario was kept" in first.stderr, first.stderr[-2000:]
    key = "user file limits.json read by myfail (SHA-256)"  # named beside the plug-in that read it
    recorded = json.loads((tmp_path / "loop" / "loop.json").read_text())[CODE_IDENTITY]
    assert recorded[key] == file_sha256(limits)  # read by the mining workers only
    again = _loop(plugins, tmp_path)  # unchanged: resumes (nothing is left to do)
    assert again.returncode == first.returncode, again.stderr[-2000:]
    before = file_sha256(limits)
    limits.write_text('{"speed": 1000.0}', encoding="utf-8")
    changed = _loop(plugins, tmp_path)
    assert changed.returncode == 2
    line = changed.stderr.strip().splitlines()[-1]
    assert "holds a loop made with other code (files the code read differ: " in line
    assert f"{key}: run has {before[:12]}, now {file_sha256(limits)[:12]}" in line
    assert "start a new --out folder" in line
