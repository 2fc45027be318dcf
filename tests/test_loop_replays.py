"""Exact replays without a conversion: one failing scene kept as a bank entry, and one per cluster of a mining run.

Failure records come from the miner's worker (``keep_lane``, which runs into what stands in its lane), as in
``test_mining_convert.py``.
"""

from __future__ import annotations

import json

import pytest

from dv2s_gym.mining.convert import replay_failure_entry
from dv2s_gym.mining.exact_replay import replay_failure
from scenario_bank.bank import Bank
from test_mining_convert import SCENARIO, make_record, midpoint


@pytest.fixture(scope="module")
def record() -> dict:
    return make_record(SCENARIO, 0, midpoint(SCENARIO))


def test_a_failure_is_kept_as_its_exact_replay_without_a_video_or_a_script(record, tmp_path):
    out = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", policy="keep_lane",
                               bank=tmp_path / "bank", monitor={})
    assert out["status"] == "kept" and out["reason"] is None and out["scenario"] == SCENARIO, out
    bank = Bank(tmp_path / "bank")
    entry = bank.get(out["replay_entry"])
    assert {"mined", "replay", "collision"} <= set(entry.tags) and entry.source["parent"] == SCENARIO
    assert entry.source["video"] is None and entry.source["trace"] == "trace.json.gz"
    assert not entry.missing_files() and (entry.folder / "trace.json.gz").is_file()
    assert entry.source["interaction"]["failure_type"] == "collision" and entry.source["e2e_sc"] == 1.0
    assert replay_failure(bank, out["replay_entry"]).get("matches") is True  # the recorded episode, step for step
    again = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", policy="keep_lane", bank=bank,
                                 monitor={})
    assert again["replay_entry"] == out["replay_entry"] and len(bank) == len(Bank(tmp_path / "bank"))


def test_a_replay_that_does_not_match_the_recorded_episode_is_rejected_and_adds_nothing(record, tmp_path):
    tampered = json.loads(json.dumps(record))
    tampered["result"]["trajectory_hash"] = "0" * 64
    out = replay_failure_entry(tampered, tmp_path / "run", policy="keep_lane", bank=tmp_path / "bank", monitor={})
    assert out["status"] == "rejected" and out["replay_entry"] is None
    assert out["reason"].startswith("replay: ") and "does not replay the failing episode" in out["reason"]
    assert not [e for e in Bank(tmp_path / "bank") if e.source.get("kind") == "mined"]
    missing = replay_failure_entry({**record, "failure": None}, tmp_path / "run", policy="keep_lane",
                                   bank=tmp_path / "bank", monitor={})
    assert missing["status"] == "rejected" and missing["reason"].startswith("input: ")


@pytest.mark.slow
def test_every_cluster_of_a_mining_run_gets_its_replay_once(tmp_path):
    from dv2s_gym.mining.cluster import group
    from dv2s_gym.mining.miner import mine, read_records
    from dv2s_gym.mining.replays import REPLAYS_FILE, replay_clusters, replay_entries

    run_dir = tmp_path / "run"
    mine("keep_lane", out=run_dir, budget=4, sampler="random", scenarios=[SCENARIO], workers=1, reference=None,
         progress=False, reports=False)  # the shipped bank mined; the replays go to another bank
    clusters = set(group(read_records(run_dir / "episodes.jsonl")))
    assert clusters, "keep_lane fails on this scenario"
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", max_replays=1, progress=False)
    assert len(rows) == 1 and rows[0]["status"] == "kept"
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", progress=False)  # resumed: the rest only
    assert sorted(r["cluster"] for r in rows) == sorted(clusters) and len(rows) == len(clusters)
    assert len((run_dir / REPLAYS_FILE).read_text().splitlines()) == len(clusters)
    entries = replay_entries(run_dir)
    kept = {r["replay_entry"] for r in rows if r["replay_entry"]}
    assert {e["scenario"] for e in entries} == kept and {e["parent"] for e in entries} == {SCENARIO}
    bank = Bank(tmp_path / "bank")
    assert all(replay_failure(bank, name).get("matches") for name in kept)
