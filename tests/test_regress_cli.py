"""`dv2s regress` and `dv2s replay REPORT --episode ID` on the command line: exit codes, output, bad input,
and a run killed mid-way that resumes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from dv2s_gym.cli import main

ROOT = Path(__file__).resolve().parents[1]
QUICK = ["--config", '{"duration": 3}', "--stall-seconds", "1", "--no-progress"]


def regress(*args: str) -> int:
    return main(["regress", *args])


@pytest.fixture(scope="module")
def failing_run(tmp_path_factory):
    """A degraded copy against the original on one scenario: the CLI's FAIL."""
    out = tmp_path_factory.mktemp("fail")
    code = regress("--policy", "rule?action_noise=0.5", "--baseline", "rule", "--scenarios",
                   "urban_lead_vehicle_stopped", "--episodes", "8", "--workers", "2", "--out", str(out), "--no-progress")
    return code, out


@pytest.mark.slow
def test_fail_exits_1_and_names_the_scenario(failing_run, capsys):
    code, out = failing_run
    assert code == 1
    report = json.loads((out / "report.json").read_text())
    assert report["verdict"] == "FAIL" and report["regressed"] == ["urban_lead_vehicle_stopped"]
    cases = ET.parse(out / "junit.xml").getroot().findall(".//testcase")
    assert [c.get("name") for c in cases] == ["urban_lead_vehicle_stopped", "overall verdict"]
    assert all(c.find("failure") is not None for c in cases)
    assert "| `urban_lead_vehicle_stopped` | 8 |" in (out / "report.md").read_text()


@pytest.mark.slow
def test_inconclusive_exits_3(tmp_path, capsys):
    code = regress("--policy", "rule", "--baseline", "rule", "--scenarios", "highway_lead_vehicle_brakes",
                   "--episodes", "2", "--workers", "1", "--out", str(tmp_path), *QUICK)
    printed = capsys.readouterr().out
    assert code == 3
    assert "verdict: INCONCLUSIVE" in printed and "highway_lead_vehicle_brakes" in printed


@pytest.mark.slow
def test_a_policy_that_crashes_in_every_episode_is_never_green(tmp_path, capsys):
    broken = "regress_helpers:BrokenPolicy"
    code = regress("--policy", broken, "--baseline", "rule", "--scenarios", "highway_lead_vehicle_brakes",
                   "--episodes", "2", "--workers", "1", "--out", str(tmp_path / "paired"), *QUICK)
    printed = capsys.readouterr().out
    assert code == 4 and "verdict: ERROR" in printed and "broken policy: no action" in printed
    suite = ET.parse(tmp_path / "paired" / "junit.xml").getroot().find("testsuite")
    assert int(suite.get("errors")) >= 1 and suite.find("testcase/error") is not None
    # measures only: still ERROR, exit 4; and that report cannot be a baseline
    code = regress("--policy", broken, "--scenarios", "highway_lead_vehicle_brakes", "--episodes", "2",
                   "--workers", "1", "--out", str(tmp_path / "alone"), *QUICK)
    assert code == 4 and "verdict: ERROR" in capsys.readouterr().out
    code = regress("--policy", "rule", "--baseline-report", str(tmp_path / "alone" / "report.json"), "--workers", "1",
                   "--out", str(tmp_path / "next"), *QUICK)
    err = capsys.readouterr().err
    assert code == 2 and "cannot be a baseline: 2 of its episodes ended in an error" in err
    assert not (tmp_path / "next" / "results.jsonl").exists()


@pytest.mark.slow
def test_pass_exits_0(tmp_path, capsys):
    # 20 pairs without a failure on either side: the interval's upper end (16 points) is below a 20-point margin
    code = regress("--policy", "rule", "--baseline", "rule", "--scenarios", "highway_lead_vehicle_brakes",
                   "highway_cut_in_from_left", "--episodes", "10", "--margin", "0.2", "--workers", "2",
                   "--out", str(tmp_path), *QUICK)
    assert code == 0
    assert "verdict: PASS" in capsys.readouterr().out


@pytest.mark.slow
def test_no_baseline_exits_0_and_json_prints_the_report(tmp_path, capsys):
    code = regress("--policy", "rule", "--scenarios", "highway_lead_vehicle_brakes", "--episodes", "2",
                   "--workers", "1", "--out", str(tmp_path), "--json", *QUICK)
    assert code == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # the opening line goes to stderr: stdout is the report's alone
    assert report["verdict"] is None and report["schema"] == "dv2s-regress"
    assert captured.err.startswith("measuring rule alone (no baseline: no verdict): 2 episodes, 1 scenario x 2 seeds; "
                                   "to compare, add --baseline POLICY"), captured.err


def test_a_run_without_baseline_opens_by_saying_it_measures_the_policy_alone():
    from dv2s_gym.cli.regress import opening_line

    from dv2s_gym.regress.runner import RegressSettings, run_size

    assert opening_line("keep_lane", 40, 40) == ("measuring keep_lane alone (no baseline: no verdict): 1600 episodes, "
                                                 "40 scenarios x 40 seeds; to compare, add --baseline POLICY (e.g. "
                                                 "--baseline rule) or --baseline-report REPORT.json")
    assert run_size(RegressSettings(scenarios=["tag:highway"], episodes=3))[1] == 3
    scenarios, seeds = run_size(RegressSettings())  # the whole bank, seeds planned from --mde and --power
    assert scenarios > 10 and seeds > 1


@pytest.mark.slow
def test_bad_input_exits_2_with_one_line(failing_run, tmp_path, capsys):
    _, out = failing_run
    assert regress("--policy", "rule", "--baseline", "rule", "--scenarios", "", "--out", str(tmp_path / "a")) == 2
    assert "dv2s: error: the scenario selection is empty" in capsys.readouterr().err
    assert regress("--policy", "rule", "--baseline", "rule", "--scenarios", "tag:no-such-tag",
                   "--out", str(tmp_path / "b")) == 2
    assert "no scenario carries tag 'no-such-tag'" in capsys.readouterr().err
    old = json.loads((out / "report.json").read_text())
    old["schema_version"] = 7
    (tmp_path / "v7.json").write_text(json.dumps(old))
    assert regress("--policy", "rule", "--baseline-report", str(tmp_path / "v7.json"), "--out", str(tmp_path / "c")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "schema version 7, this dv2s-gym reads version 4" in err
    assert regress("--policy", "rule", "--baseline", "rule", "--config", "{duration: 3", "--out", str(tmp_path)) == 2
    assert "--config must be a JSON object" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # argparse: the two baselines exclude each other
        regress("--policy", "rule", "--baseline", "rule", "--baseline-report", "x.json")
    assert exit_info.value.code == 2


@pytest.mark.slow
def test_baseline_report_reruns_only_the_candidate(failing_run, tmp_path, capsys):
    _, out = failing_run
    # a report whose verdict was FAIL is no baseline, unless asked for explicitly
    assert regress("--policy", "rule", "--baseline-report", str(out / "report.json"), "--workers", "2",
                   "--out", str(tmp_path / "refused"), "--no-progress") == 2
    assert "has the verdict FAIL" in capsys.readouterr().err and not (tmp_path / "refused").exists()
    code = regress("--policy", "rule", "--baseline-report", str(out / "report.json"), "--workers", "2",
                   "--out", str(tmp_path), "--no-progress", "--accept-failed-baseline")
    printed = capsys.readouterr().out
    assert f"(the candidate policy of {out / 'report.json'})" in printed  # which of its policies is the baseline
    report = json.loads((tmp_path / "report.json").read_text())
    # the report's tested policy (the noisy copy) is the baseline now; the original does not fail more
    assert report["settings"]["episodes"] == 8 and report["baseline"]["spec"] == "rule?action_noise=0.5"
    # the power plan wanted more episodes than the baseline report has: said, and the power stated
    plan = report["settings"]["plan"]
    assert plan["planned"] > 8 and "fewer than the" in plan["note"]
    assert "has less power than planned" in printed
    assert code in (0, 3) and report["verdict"] != "FAIL"
    lines = (tmp_path / "results.jsonl").read_text().splitlines()
    assert len(lines) == 8 and {json.loads(line)["role"] for line in lines} == {"candidate"}


@pytest.mark.slow
def test_replay_an_episode_of_a_report(failing_run, tmp_path, capsys):
    _, out = failing_run
    report = json.loads((out / "report.json").read_text())
    episode = report["newly_failing"][0]
    video = tmp_path / "episode.webm"
    assert main(["replay", str(out / "report.json"), "--episode", episode, "--video", str(video)]) == 0
    printed = capsys.readouterr().out
    assert "trace replayed, every actor state matches" in printed and "matches the report" in printed
    assert video.stat().st_size > 0
    assert main(["replay", str(out / "report.json"), "--episode", episode, "--policy", "baseline"]) == 0
    assert "policy re-run" in capsys.readouterr().out

    assert main(["replay", str(out / "report.json")]) == 2
    assert "--episode SCENARIO/SEED" in capsys.readouterr().err
    tampered = json.loads(json.dumps(report))
    target = next(e for e in tampered["episodes"] if e["id"] == episode)
    target["candidate"]["trajectory_hash"] = "0" * 64
    target["candidate"]["trace"] = str(out / target["candidate"]["trace"])
    (tmp_path / "tampered.json").write_text(json.dumps(tampered))
    assert main(["replay", str(tmp_path / "tampered.json"), "--episode", episode]) == 1
    assert "DIFFERS from the report" in capsys.readouterr().out


@pytest.mark.slow
def test_a_killed_run_resumes_without_losing_or_repeating_episodes(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["regress", "--policy", "rule", "--baseline", "keep_lane", "--scenarios", "highway_lead_vehicle_brakes",
            "highway_cut_in_from_left", "--episodes", "10", "--workers", "1", "--out", str(out), "--no-progress"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    process = subprocess.Popen([sys.executable, "-m", "dv2s_gym.cli", *args], cwd=ROOT, env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    results = out / "results.jsonl"
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and process.poll() is None:
            if results.is_file() and results.read_text().count("\n") >= 4:
                break
            time.sleep(0.05)
    finally:
        os.killpg(process.pid, signal.SIGKILL)  # the run and its workers, mid-episode
        process.wait()
    before = [json.loads(line) for line in results.read_text().splitlines() if line.endswith("}")]
    assert 4 <= len(before) < 40, "the run should have been killed part-way"

    assert main(args) in (0, 1, 3)  # a verdict, whichever: the run completed
    keys = [(r["id"], r["role"]) for r in map(json.loads, results.read_text().splitlines())]
    assert len(keys) == len(set(keys)) == 40
    assert {(r["id"], r["role"]) for r in before} <= set(keys)
    kept = {(r["id"], r["role"]): r for r in map(json.loads, results.read_text().splitlines())}
    assert all(kept[(r["id"], r["role"])] == r for r in before)  # finished episodes were not run again
    report = json.loads((out / "report.json").read_text())
    assert len(report["episodes"]) == 20 and not report["errors"]


def test_regress_help_documents_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["regress", "--help"])
    text = capsys.readouterr().out
    assert "0 PASS" in text and "1 FAIL" in text and "3 INCONCLUSIVE" in text and "2 bad input" in text and "4 ERROR" in text
