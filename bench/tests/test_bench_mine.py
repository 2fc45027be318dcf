"""bench/bench_mine.py's one mining run (``mine_once``), which every part of the mining benchmark repeats: it runs
the miner as ``dv2s mine`` does and counts what the breadth tables print."""

from __future__ import annotations

from bench.bench_mine import mine_once


def test_one_mining_run_counts_failures_clusters_pairs_and_the_rate(tmp_path):
    row = mine_once("keep_lane", "random", 0, 4, 1, None, ["highway_lead_vehicle_stopped", "urban_lead_vehicle_stopped"],
                    None, str(tmp_path / "run"), feedback=None)
    assert row["episodes"] == 4 and row["errors"] == 0
    assert 0 <= row["failures"] <= 4 and row["clusters"] <= row["failures"]
    assert row["scenarios_failing"] <= 2 and row["kinds"] <= row["failures"]
    assert isinstance(row["collapsed"], bool)
    assert row["rate"] is not None and 0.0 <= row["rate"][1] <= row["rate"][0] <= row["rate"][2] <= 1.0


def test_the_breadth_table_without_random_says_how_to_get_ratios_instead_of_printing_nan(monkeypatch, capsys):
    import bench.bench_mine as bench

    row = {"failures": 3, "episodes": 6, "errors": 0, "clusters": 2, "kinds": 2, "scenarios_failing": 1,
           "rate": None, "seconds": 1.0}
    monkeypatch.setattr(bench, "mine_once", lambda *args, **kwargs: dict(row))
    summary = bench.bench_breadth(["keep_lane"], ["novelty-bandit"], [0], 6, 1, None, None, "/nonexistent")
    out = capsys.readouterr().out
    assert "nan" not in out.lower() and "add random to --samplers" in out
    assert all(value is None for value in summary["per_policy"][("keep_lane", "novelty-bandit")]["ratios"].values())
    bench.bench_breadth(["keep_lane"], ["random", "novelty-bandit"], [0], 6, 1, None, None, "/nonexistent")
    assert "1.00x" in capsys.readouterr().out
