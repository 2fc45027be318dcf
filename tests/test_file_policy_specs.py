"""A policy spec read from a file (a mining run's settings.json, a regress report) is data: only a built-in
policy is loaded from it; anything else (module:attribute, a checkpoint) needs the user's --policy-spec."""

from __future__ import annotations

import json
import re

import pytest

from cli_helpers import one_line_error, run
from policies.registry import PolicyError, spec_from_file

PAYLOAD = '''
from pathlib import Path
Path(__file__).with_name("loaded.txt").write_text("loaded")

def make():
    Path(__file__).with_name("called.txt").write_text("called")
    raise RuntimeError("the explicit policy was loaded")
'''


@pytest.mark.parametrize("spec", ["rule", "idm?time_headway=2.0", "random?seed=3", "rule?action_noise=0.25&noise_seed=1",
                                  "keep_lane", "dv2s-ppo"])
def test_builtin_specs_from_a_file_are_accepted(spec):
    assert spec_from_file(spec, "settings.json", "--policy-spec SPEC") == spec


@pytest.mark.parametrize("spec", ["subprocess:run?args=id&shell=true", "marker:make", "ppo:/tmp/model.zip",
                                  "model.zip", "/tmp/run", "rule?device=cuda", "dv2s-ppo?custom_objects=x",
                                  "rule?action_noise=nan", "rule?=1", None, 3])
def test_other_specs_from_a_file_are_refused_naming_the_fix(spec):
    with pytest.raises(PolicyError, match="not a built-in policy.*--policy-spec SPEC"):
        spec_from_file(spec, "settings.json", "--policy-spec SPEC")


@pytest.fixture
def payload(tmp_path, monkeypatch):
    (tmp_path / "marker.py").write_text(PAYLOAD)
    monkeypatch.chdir(tmp_path)  # a module in the current directory is importable by a module:attribute spec
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def test_replay_of_a_mining_run_does_not_load_its_settings_policy(capsys, payload):
    folder = payload / "run"
    folder.mkdir()
    (folder / "settings.json").write_text(json.dumps({"schema": "dv2s-mine-run", "policy": "marker:make",
                                                      "bank_dir": None, "env_config": {}}))
    (folder / "episodes.jsonl").write_text(json.dumps({"index": 0, "scenario": "highway_lead_vehicle_brakes",
                                                       "seed": 0, "params": {},
                                                       "result": {"trajectory_hash": "00"}}) + "\n")
    code, _, err = run(capsys, "replay", folder, "--episode", "0")
    line = one_line_error(err)
    assert code == 2 and "'marker:make'" in line and "--policy-spec" in line
    assert not (payload / "loaded.txt").exists() and not (payload / "called.txt").exists()

    code, _, err = run(capsys, "replay", folder, "--episode", "0", "--policy-spec", "marker:make")
    assert (payload / "called.txt").exists()  # the user's own --policy-spec is loaded
    assert code == 2 and "the explicit policy was loaded" in err


def test_replay_of_a_report_episode_does_not_load_the_reports_policy(capsys, payload):
    report = {"schema": "dv2s-regress", "schema_version": 4, "candidate": {"spec": "marker:make"},
              "bank": {"hashes": {}}, "settings": {"env_config": {}, "failure": ["collision", "off_road"]},
              "episodes": [{"id": "highway_lead_vehicle_brakes/0",
                            "candidate": {"scenario": "highway_lead_vehicle_brakes", "seed": 0,
                                          "trajectory_hash": "00", "failed": True}}],
              "newly_failing": ["highway_lead_vehicle_brakes/0"]}
    path = payload / "report.json"
    path.write_text(json.dumps(report))
    code, _, err = run(capsys, "replay", path, "--episode", "highway_lead_vehicle_brakes/0")
    line = one_line_error(err)
    assert code == 2 and "'marker:make'" in line and "--policy-spec" in line
    assert not (payload / "loaded.txt").exists() and not (payload / "called.txt").exists()


def test_a_baseline_reports_policy_is_not_rerun_for_a_clip(tmp_path):
    from dv2s_gym.regress.clips import ClipError, render_policy_video
    from dv2s_gym.regress.records import RegressReport
    from scenario_bank.records import RegressEpisode

    report = RegressReport.from_dict({"baseline": {"spec": "marker:make", "report": str(tmp_path / "old.json")}})
    result = RegressEpisode.from_dict({"id": "highway_lead_vehicle_brakes/0", "role": "baseline",
                                       "scenario": "highway_lead_vehicle_brakes", "seed": 0})
    with pytest.raises(ClipError, match="not a built-in policy"):
        render_policy_video(report, result, "baseline", tmp_path / "clip.webm")


def test_replay_of_a_mining_run_bounds_its_env_config(capsys, tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "settings.json").write_text(json.dumps({
        "schema": "dv2s-mine-run", "policy": "rule", "bank_dir": None,
        "env_config": {"observation": {"type": "Kinematics", "vehicles_count": 50_000_000}}}))
    (folder / "episodes.jsonl").write_text(json.dumps({"index": 0, "scenario": "highway_lead_vehicle_brakes",
                                                       "seed": 0, "params": {},
                                                       "result": {"trajectory_hash": "00"}}) + "\n")
    code, _, err = run(capsys, "replay", folder, "--episode", "0")
    line = one_line_error(err)
    assert code == 2 and "observation.vehicles_count=50000000" in line and "settings.json" in line


def test_replay_of_a_report_episode_bounds_its_env_config(tmp_path):
    from dv2s_gym.regress.replay import replay_episode
    from envs.trace_bounds import TraceConfigError

    report = {"schema": "dv2s-regress", "schema_version": 4, "candidate": {"spec": "rule"},
              "bank": {"hashes": {}}, "settings": {"env_config": {"screen_width": 10**6}, "failure": ["collision", "off_road"]},
              "episodes": [{"id": "highway_lead_vehicle_brakes/0",
                            "candidate": {"scenario": "highway_lead_vehicle_brakes", "seed": 0,
                                          "trajectory_hash": "00", "failed": False}}]}
    path = tmp_path / "report.json"
    path.write_text(json.dumps(report))
    with pytest.raises(TraceConfigError, match="env_config of the report has screen_width=1000000"):
        replay_episode(path, "highway_lead_vehicle_brakes/0")


def test_a_bank_replay_entry_names_a_policy_only_if_it_is_built_in(tmp_path):
    from dv2s_gym.mining.conversion.exact_replay import replay_failure
    from scenario_bank.bank import Bank
    from scenario_bank.records import Provenance

    class Entry:
        source = Provenance.from_dict({"replay": {"seed": 0, "policy": "marker:make"}})
        script_path = tmp_path / "scenario.scenic"

    class FakeBank(Bank):
        def __init__(self):
            pass

        def get(self, name):
            return Entry()

    with pytest.raises(PolicyError, match="bank entry 'x'.*policy=SPEC"):
        replay_failure(FakeBank(), "x")


@pytest.mark.parametrize("episode, says", [(None, "name the episode with --episode INDEX"),
                                           ("7", "episode 7 of .* did not finish")])
def test_replay_of_a_mining_run_without_a_finished_episode_names_the_fix(capsys, tmp_path, episode, says):
    """A user's mistake on a mining run folder is one line naming the fix, not an unexpected error."""
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "settings.json").write_text(json.dumps({"schema": "dv2s-mine-run", "policy": "rule",
                                                      "bank_dir": None, "env_config": {}}))
    (folder / "episodes.jsonl").write_text(json.dumps({"index": 0, "scenario": "highway_lead_vehicle_brakes",
                                                       "seed": 0, "params": {}, "result": None}) + "\n")
    code, _, err = run(capsys, "replay", folder, *([] if episode is None else ["--episode", episode]))
    line = one_line_error(err)
    assert code == 2 and re.search(says, line) and "unexpected" not in err and "--debug" not in err
