"""`dv2s loop` end to end with the real miner, converter, fine-tuning and regression test, at a tiny scale:
what the report says is what the working bank and the run folders hold."""

from __future__ import annotations

import json

import pytest

from scenario_bank.bank import Bank
from tests.cli_helpers import run

SCENARIOS = ["highway_lead_vehicle_brakes", "highway_truck_cut_in"]


@pytest.mark.slow
def test_one_round_of_the_real_loop(tmp_path, capsys):
    out = tmp_path / "loop"
    code, stdout, err = run(capsys, "loop", "--policy", "dv2s-ppo", "--scenarios", *SCENARIOS, "--budget", "16",
                            "--fine-tune-steps", "256", "--k-eval", "2", "--regress-episodes", "1", "--workers", "2",
                            "--envs", "1", "--out", out, "--no-progress")
    assert code in (0, 1, 3), err  # the verdict on the fine-tuned policy: ACCEPTED, REJECTED, NOT ACCEPTED
    assert f"report (html): {out / 'report.html'}" in stdout

    report = json.loads((out / "report.json").read_text())
    verdict = report["recommendation"]
    assert code == verdict["exit_code"] and f"verdict: {verdict['sentence']}" in stdout
    assert verdict["candidate"] == report["policy"] and f"policy to use: {verdict['policy']}" in stdout
    steps = report["rounds"][0]["steps"]
    mine_dir = out / "round_1" / "mine"
    episodes = [json.loads(line) for line in (mine_dir / "episodes.jsonl").read_text().splitlines()]
    conversions = [json.loads(line) for line in (mine_dir / "conversions.jsonl").read_text().splitlines()]
    assert len(episodes) == 16 and {e["scenario"] for e in episodes} <= set(SCENARIOS)
    failures = [e for e in episodes if e["failure"] and not e["error"]]
    assert steps["mine"]["episodes"] == 16 and steps["mine"]["failures"] == len(failures) > 0
    assert (mine_dir / "report.html").is_file() and (mine_dir / "report.json").is_file()

    # every conversion ended kept, merged or rejected with a reason; kept ones are in the working bank as mined
    bank = Bank(out / "bank")
    shipped = set(Bank().names())
    assert shipped <= set(bank.names())
    kept = {c["bank_entry"] for c in conversions if c["status"] == "kept"}
    replay_rows = [json.loads(line) for line in (mine_dir / "replays.jsonl").read_text().splitlines()] \
        if (mine_dir / "replays.jsonl").is_file() else []
    assert all(row["status"] == "kept" or row["reason"] for row in replay_rows)
    assert not {r["cluster"] for r in replay_rows} & {c["cluster"] for c in conversions}  # one replay per cluster
    # the failing scenes, kept exactly: those of the converted clusters and those of the others (replays.jsonl)
    replays = {c["replay_entry"] for c in conversions + replay_rows if c.get("replay_entry")}
    mined = {e.name for e in bank if e.source.kind == "mined"}
    assert replays and mined == kept | replays and set(bank.names()) == shipped | kept | replays
    for name in replays:
        assert "replay" in bank.get(name).tags and bank.get(name).source.parent in SCENARIOS
    for row in conversions:
        assert row["status"] in ("kept", "merged", "rejected")
        if row["status"] == "rejected":
            assert row["reason"]
        else:
            assert row["reproduction"]["rate"] >= 0.3
    for name in kept:
        source = bank.get(name).source.to_dict()
        assert source["parent"] in SCENARIOS and source["reproduction"]["rate"] >= 0.3
        assert (bank.get(name).folder / source["video"]).is_file()  # carried in the entry folder

    # the split holds every kept scenario and exact replay once; the held-out ones ran before and after on the
    # same episodes
    split = steps["split"]
    assert set(split["fine_tune"]) | set(split["held_out"]) == kept | replays
    assert not set(split["fine_tune"]) & set(split["held_out"])
    if split["held_out"]:
        assert steps["after"]["pairs"] == 2 * len(split["held_out"])
        assert steps["regress"]["verdict"] in ("PASS", "FAIL", "INCONCLUSIVE")
