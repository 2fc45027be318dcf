"""A policy spec read from a file (a mining run's settings.json, a regress report) is data: only a built-in
policy is loaded from it; anything else (module:attribute, a checkpoint) needs the user's --policy-spec."""

from __future__ import annotations

import json

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
    report = {"schema": "dv2s-regress", "schema_version": 1, "candidate": {"spec": "marker:make"},
              "bank": {"hashes": {}}, "settings": {"env_config": {}},
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

    report = {"baseline": {"spec": "marker:make", "report": str(tmp_path / "old.json")}}
    with pytest.raises(ClipError, match="not a built-in policy"):
        render_policy_video(report, {"scenario": "highway_lead_vehicle_brakes", "seed": 0}, "baseline",
                            tmp_path / "clip.webm")
