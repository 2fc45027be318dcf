"""The labelled description set (dv2s_gym/evalset/descriptions): complete, valid and sourced."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from dv2s_gym.pipeline.evaluate import collect_items
from dv2s_gym.pipeline.labels import LABEL_SUFFIX, read_label
from scenario_bank.elements import PARTICIPANTS, Elements

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
    elements = Elements.from_dict(data["elements"])
    assert data["use_case"] in GROUPS
    participants = elements.participants
    assert participants.count("ego") == 1
    for who, action in elements.actions:
        assert who in participants, f"action {who} {action} of an actor not in participants"
    for a, _, b in elements.relations:
        assert a in participants and b in participants and b == "ego" and a != "ego"
    # a collision has a type and two parties
    colliders = [who for who, action in elements.actions if action == "collide"]
    for who in set(p for p in PARTICIPANTS):
        actions = {action for w, action in elements.actions if w == who}
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


def test_clip_evalset_does_not_read_the_descriptions():
    """`dv2s eval dra|e2e` on the clip set (the parent folder) sees no description of this subfolder."""
    stems = {item.stem for item in collect_items(FOLDER.parent)}
    assert stems and not stems & _stems(".txt")
