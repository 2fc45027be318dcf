"""bench/bench_sg_descriptions.py, the benchmark of the SG on the labelled description set
(dv2s_gym/evalset/descriptions): its analysis, its comparison of two runs and its shipped baseline."""

from __future__ import annotations

import json
from pathlib import Path

from bench.bench_sg_descriptions import analyse, compare
from dv2s_gym.pipeline.labels import read_label

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "dv2s_gym" / "evalset" / "descriptions"


def _stems(suffix: str) -> set[str]:
    return {p.name[: -len(suffix)] for p in FOLDER.glob(f"*{suffix}")}


def test_bench_analysis_counts_lost_elements_and_silent_drops():
    stem = "nhtsa_lead_stopped_a"  # straight_road; ego, car; car stop; car ahead_of ego; car same_lane ego
    exact = read_label(FOLDER / f"{stem}.label.json").elements.to_dict()
    partial = dict(exact, actions=[], relations=[["car", "ahead_of", "ego"]])
    report = {"items": [
        {"stem": stem, "use_case": "nhtsa_typology", "metrics": {"SP": 1.0}, "ok": True,
         "detail": {"simulated": exact, "warnings": []}},
        {"stem": stem, "use_case": "nhtsa_typology", "metrics": {"SP": 0.6}, "ok": True,
         "detail": {"simulated": partial, "warnings": []}},
        {"stem": stem, "use_case": "crash_report", "metrics": {"SP": 0.0}, "ok": False,
         "detail": {"simulated": None, "warnings": ["could not place 'x': no participant type"]}},
    ]}
    result = analyse(report)
    assert result["runs"] == 2 and result["items"] == 3
    assert result["groups"]["nhtsa_typology"]["SP"] == "0.800 ± 0.283"
    assert dict(result["lost"])["action car stop"] == 2
    assert dict(result["lost"])["relation car same_lane ego"] == 2
    assert result["lost_by_kind"]["road"] == "1/3"
    assert result["silent_drops"] == 1  # the second item lost elements and said nothing
    assert result["warnings"] == [("could not place 'x'", 1)]


def test_bench_compare_lists_worse_descriptions():
    before = {"a": {"SP": 0.5, "ok": True}, "b": {"SP": 1.0, "ok": True}, "gone": {"SP": 0.0, "ok": False}}
    after = {"a": {"SP": 0.75, "ok": True}, "b": {"SP": 0.5, "ok": False}, "new": {"SP": 1.0, "ok": True}}
    delta = compare(before, after)
    assert delta["n"] == 2 and delta["before"] == 0.75 and delta["after"] == 0.625
    assert delta["worse"] == [("b", 1.0, 0.5)] and delta["better"] == ["a"]
    assert (delta["runs_before"], delta["runs_after"]) == (2, 1)


def test_shipped_baseline_scores_every_description():
    baseline = json.loads((ROOT / "bench" / "research" / "sg_descriptions_baseline.json").read_text())
    assert set(baseline) <= _stems(".txt") and len(baseline) >= 130  # no stale stem; batch 1 + 2 scored
    assert all(0.0 <= row["SP"] <= 1.0 for row in baseline.values())
