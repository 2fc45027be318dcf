"""The labelled description set (dv2s_gym/evalset/descriptions): complete, valid and sourced."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from dv2s_gym.pipeline.evaluate import collect_items
from dv2s_gym.pipeline.labels import LABEL_SUFFIX, read_label
from scenario_bank.elements import PARTICIPANTS, normalize_elements

FOLDER = Path(__file__).resolve().parents[1] / "dv2s_gym" / "evalset" / "descriptions"
GROUPS = {"nhtsa_typology", "crash_report", "test_protocol", "engineer_notes", "benchmark_prompt"}


def _stems(suffix: str) -> set[str]:
    return {p.name[: -len(suffix)] for p in FOLDER.glob(f"*{suffix}")}


def test_every_description_has_a_label_and_back():
    texts, labels = _stems(".txt"), _stems(LABEL_SUFFIX)
    assert texts == labels, f"without label: {sorted(texts - labels)}; without text: {sorted(labels - texts)}"
    assert len(texts) >= 80


@pytest.mark.parametrize("path", sorted(FOLDER.glob(f"*{LABEL_SUFFIX}")), ids=lambda p: p.name)
def test_label_is_valid_and_consistent(path):
    data = json.loads(path.read_text(encoding="utf-8"))
    elements = normalize_elements(data["elements"])
    assert data["use_case"] in GROUPS
    participants = elements["participants"]
    assert participants.count("ego") == 1
    for who, action in elements["actions"]:
        assert who in participants, f"action {who} {action} of an actor not in participants"
    for a, _, b in elements["relations"]:
        assert a in participants and b in participants and b == "ego" and a != "ego"
    # a collision has a type and two parties
    colliders = [who for who, action in elements["actions"] if action == "collide"]
    for who in set(p for p in PARTICIPANTS):
        actions = {action for w, action in elements["actions"] if w == who}
        assert ("collide" in actions) == bool(actions & {"collide_rear_end", "collide_side", "collide_head_on"})
    assert len(colliders) != 1
    assert read_label(path).use_case == data["use_case"]
    text = path.with_name(path.name[: -len(LABEL_SUFFIX)] + ".txt").read_text(encoding="utf-8")
    assert text.strip()


def test_sources_cover_every_stem_and_group():
    sources = (FOLDER / "SOURCES.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"`([a-z0-9_]+)`", sources))
    missing = _stems(".txt") - listed
    assert not missing, f"stems not listed in SOURCES.md: {sorted(missing)}"
    for group in GROUPS:
        assert f"## {group}:" in sources


def test_eval_sg_reads_the_folder_with_labels():
    items = collect_items(FOLDER, unlabeled_descriptions=True)
    assert len(items) == len(_stems(".txt"))
    assert all(item.elements is not None and item.description for item in items)
    assert {item.use_case for item in items} == GROUPS


def test_bench_analysis_counts_lost_elements_and_silent_drops():
    from bench.bench_sg_descriptions import analyse

    stem = "nhtsa_lead_stopped_a"  # straight_road; ego, car; car stop; car ahead_of ego; car same_lane ego
    exact = read_label(FOLDER / f"{stem}.label.json").elements
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


def test_clip_evalset_does_not_read_the_descriptions():
    """`dv2s eval dra|e2e` on the clip set (the parent folder) sees no description of this subfolder."""
    stems = {item.stem for item in collect_items(FOLDER.parent)}
    assert stems and not stems & _stems(".txt")


def test_bench_compare_lists_worse_descriptions():
    from bench.bench_sg_descriptions import compare

    before = {"a": {"SP": 0.5, "ok": True}, "b": {"SP": 1.0, "ok": True}, "gone": {"SP": 0.0, "ok": False}}
    after = {"a": {"SP": 0.75, "ok": True}, "b": {"SP": 0.5, "ok": False}, "new": {"SP": 1.0, "ok": True}}
    delta = compare(before, after)
    assert delta["n"] == 2 and delta["before"] == 0.75 and delta["after"] == 0.625
    assert delta["worse"] == [("b", 1.0, 0.5)] and delta["better"] == ["a"]
    assert (delta["runs_before"], delta["runs_after"]) == (2, 1)


def test_shipped_baseline_scores_every_description():
    baseline = json.loads((FOLDER.parents[2] / "bench" / "sg_descriptions_baseline.json").read_text())
    assert set(baseline) <= _stems(".txt") and len(baseline) >= 130  # no stale stem; batch 1 + 2 scored
    assert all(0.0 <= row["SP"] <= 1.0 for row in baseline.values())
