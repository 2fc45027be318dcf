"""`dv2s mine` on the command line: a run, its summary and files, bad input, and a run killed with
SIGKILL mid-way that resumes to exactly the records of an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.cli_helpers import one_line_error, run

ROOT = Path(__file__).resolve().parents[1]
QUICK = ["--config", '{"duration": 5}', "--no-progress", "--no-convert"]
SCENARIOS = ["--scenarios", "highway_lead_vehicle_brakes", "highway_cut_in_from_left"]


def keys(out: Path):
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines() if line.strip()]
    rows.sort(key=lambda r: r["index"])
    return [(r["index"], r["scenario"], r["seed"], r["params"], r["result"]["trajectory_hash"],
             r["failure"], r["avoidable"]) for r in rows]


@pytest.mark.slow
def test_mine_writes_records_settings_and_a_summary(tmp_path, capsys):
    out = tmp_path / "run"
    code, stdout, err = run(capsys, "mine", "--policy", "keep_lane", *SCENARIOS, "--budget", "8", "--workers", "2",
                            "--out", out, *QUICK)
    assert code == 0, err
    settings = json.loads((out / "settings.json").read_text())
    assert settings["policy"] == "keep_lane" and settings["sampler"] == "novelty-bandit"
    assert sorted(settings["space"]) == ["highway_cut_in_from_left", "highway_lead_vehicle_brakes"]
    records = keys(out)
    assert [r[0] for r in records] == list(range(8))
    for index, scenario, seed, params, *_ in records:
        ranges = settings["space"][scenario]
        assert set(params) == set(ranges) and "weather" not in params
        for name, value in params.items():
            assert ranges[name]["low"] <= value <= ranges[name]["high"]
    failed = [r for r in records if r[5]]
    assert stdout.splitlines()[0].startswith("8 episodes of keep_lane (novelty-bandit sampler), 0 errors")
    assert f"{len(failed)} failures" in stdout
    for record in failed:  # every failure kept its trace and was checked against the reference driver
        assert record[6] in (True, False)
        assert (out / "traces" / f"{record[0]:06d}.json.gz").is_file()


@pytest.mark.parametrize("argv, message", [
    (["--policy", "rule", "--budget", "4"], "pass --bank DIR"),
    (["--policy", "rule", "--budget", "0", "--no-convert"], "--budget must be an integer >= 1"),
    (["--policy", "no-such-policy", "--budget", "4", "--no-convert"], "unknown policy 'no-such-policy'"),
    (["--policy", "rule", "--budget", "4", "--no-convert", "--scenarios", "no_such_scenario"], "no_such_scenario"),
])
def test_bad_input_is_one_line(tmp_path, capsys, argv, message):
    code, _, err = run(capsys, "mine", *argv, "--out", tmp_path / "run", "--no-progress")
    assert code == 2
    assert message in one_line_error(err)
    assert not (tmp_path / "run").exists()  # refused input leaves no empty run folder behind


@pytest.mark.parametrize("given, meant", [
    ("nosuch", None),
    ("lead_brak", "highway_lead_vehicle_brakes"),
    (str(ROOT / "scenario_bank" / "scenarios" / "highway_cut_in_from_left" / "scenario.scenic"),
     "highway_cut_in_from_left"),
])
def test_an_unknown_scenario_says_what_mine_takes_and_what_the_bank_holds(tmp_path, capsys, given, meant):
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--no-convert", "--scenarios", given,
                       "--out", tmp_path / "run", "--no-progress")
    line = one_line_error(err)  # it offered "a path to a .scenic file, Scenic source text", which mine refuses
    assert code == 2 and "dv2s mine --scenarios takes bank names and 'tag:<tag>'" in line
    assert ".scenic file" not in line and "Scenic source text" not in line
    if given.endswith(".scenic"):
        assert "not Scenic files or text" in line and "dv2s bank add" in line
    if meant:
        assert f"Did you mean '{meant}'" in line
    else:  # nothing close: a few of the bank's names instead
        assert "Did you mean" not in line and "The bank's scenarios: 'highway_adjacent_car_drifts'" in line
    assert not (tmp_path / "run").exists()


def test_the_mining_api_refuses_an_unknown_scenario_the_same_way():
    from scenario_bank import UnknownScenarioError
    from dv2s_gym.mining.sampling.space import SceneSpace

    with pytest.raises(UnknownScenarioError, match=r"dv2s mine --scenarios takes bank names.*Did you mean "
                                                   r"'highway_lead_vehicle_brakes'"):
        SceneSpace(["lead_brak"])


def test_mining_a_bank_that_does_not_exist_names_it(tmp_path, capsys):
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--no-convert", "--bank",
                       tmp_path / "typo", "--out", tmp_path / "run", "--no-progress")
    line = one_line_error(err)  # it said only "the bank at ... holds no scenarios"
    assert code == 2 and "there is no bank at" in line and "the folder does not exist" in line
    assert not (tmp_path / "typo").exists() and not (tmp_path / "run").exists()


def test_mining_named_scenarios_of_a_bank_that_does_not_exist_names_the_bank(tmp_path, capsys):
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--no-convert", "--scenarios",
                       "highway_lead_vehicle_brakes", "--bank", tmp_path / "typo", "--out", tmp_path / "run",
                       "--no-progress")
    line = one_line_error(err)  # not "the bank ... holds no scenario 'highway_lead_vehicle_brakes'"
    assert code == 2 and "there is no bank at" in line and "the folder does not exist" in line
    assert not (tmp_path / "typo").exists() and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_an_unreachable_ray_cluster_is_one_line_and_leaves_no_run_folder(tmp_path, capsys):
    from llm_server import closed_port_url

    address = closed_port_url().split("//")[1].split("/")[0]
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "2", "--no-convert", "--backend", "ray",
                       "--address", address, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and f"Ray is not reachable at {address}" in one_line_error(err)
    assert not (tmp_path / "run").exists()  # it kept settings.json and an empty episodes.jsonl


@pytest.mark.parametrize("flag", ["--out", "--bank"])
def test_a_file_where_a_folder_belongs_is_named(tmp_path, capsys, flag):
    a_file = tmp_path / "a_file"
    a_file.write_text("mine\n")
    given = {"--out": tmp_path / "run", "--bank": tmp_path / "bank", flag: a_file}
    try:
        code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--out", given["--out"],
                           "--bank", given["--bank"], "--no-progress")
    except SystemExit as stop:  # --out is checked while the options are read
        code, err = stop.code, capsys.readouterr().err
    lines = err.strip().splitlines()  # "dv2s: error: ..." or, for --out, "dv2s mine: error: argument --out: ..."
    assert len(lines) == 1 and lines[0].startswith("dv2s") and "error: " in lines[0] and "Traceback" not in err
    assert code == 2 and flag in lines[0] and f"{a_file} is a file, not a folder" in lines[0]
    assert a_file.read_text() == "mine\n" and not (tmp_path / "run").exists() and not (tmp_path / "bank").exists()


@pytest.mark.slow
def test_resuming_with_other_settings_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    base = ["mine", "--policy", "rule", "--scenarios", "highway_lead_vehicle_brakes", "--budget", "2",
            "--workers", "1", "--out", out, *QUICK]
    assert run(capsys, *base)[0] == 0
    code, _, err = run(capsys, *base, "--sampler", "halton")
    assert code == 2
    assert "other settings (sampler: run has 'novelty-bandit', asked 'halton'" in one_line_error(err)


@pytest.mark.slow
def test_sigkill_mid_run_then_resume_equals_an_uninterrupted_run(tmp_path, capsys):
    argv = ["--policy", "keep_lane", *SCENARIOS, "--budget", "24", "--workers", "2", "--seed", "3", *QUICK]
    whole = tmp_path / "whole"
    assert run(capsys, "mine", *argv, "--out", whole)[0] == 0

    cut = tmp_path / "cut"
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    process = subprocess.Popen([sys.executable, "-m", "dv2s_gym.cli", "mine", *argv, "--out", str(cut)],
                               cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    deadline = time.monotonic() + 300
    log = cut / "episodes.jsonl"
    while time.monotonic() < deadline and process.poll() is None:
        if log.is_file() and len(log.read_bytes().splitlines()) >= 10:
            break
        time.sleep(0.05)
    assert process.poll() is None, "the run ended before it could be killed"
    os.killpg(process.pid, signal.SIGKILL)  # the miner and its workers, mid-run
    process.wait()
    finished = len([line for line in log.read_bytes().splitlines() if line.endswith(b"}")])
    assert 10 <= finished < 24

    code, stdout, err = run(capsys, "mine", *argv, "--out", cut)
    assert code == 0, err
    assert keys(cut) == keys(whole)
    assert stdout.splitlines()[0].startswith("24 episodes")


@pytest.mark.slow
def test_replay_reruns_a_mined_failure_and_writes_its_video(tmp_path, capsys):
    from dv2s_gym.pipeline.video import read_video

    out = tmp_path / "run"
    assert run(capsys, "mine", "--policy", "keep_lane", "--scenarios", "highway_lead_vehicle_stopped", "--budget",
               "4", "--workers", "1", "--out", out, *QUICK)[0] == 0
    records = keys(out)
    failed = [r for r in records if r[5]]
    assert failed, "keep_lane drives into the stopped car"
    index = failed[0][0]
    video = tmp_path / "failure.webm"
    code, stdout, err = run(capsys, "replay", out, "--episode", index, "--video", video)
    assert code == 0, err
    assert f"episode {index} (highway_lead_vehicle_stopped" in stdout and "matches the record" in stdout
    assert len(read_video(video).frames) > 5

    # a tampered record no longer replays: the hash check is real
    lines = (out / "episodes.jsonl").read_text().splitlines()
    rows = [json.loads(line) for line in lines]
    for row in rows:
        if row["index"] == index:
            row["params"] = {k: v + 0.5 if isinstance(v, float) else v for k, v in row["params"].items()}
    (out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    code, _, err = run(capsys, "replay", out, "--episode", index)
    assert code == 2 and "diverged" in one_line_error(err)
    code, _, err = run(capsys, "replay", out)
    assert code == 2 and "--episode INDEX" in one_line_error(err)


def test_mining_without_the_mining_extra_names_the_extra(tmp_path, monkeypatch):
    """The core install has no VerifAI: mining says which extra to install, in one line, before any work."""
    from dv2s_gym.mining.errors import MiningError
    from mining_helpers import mine

    monkeypatch.setitem(sys.modules, "verifai", None)  # as if it were not installed
    with pytest.raises(MiningError, match=r"pip install 'dv2s-gym\[mining\]'"):
        mine("rule", out=tmp_path / "mine", budget=2, progress=False)
    assert not (tmp_path / "mine").exists()
