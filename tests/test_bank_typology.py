"""The shipped bank against the NHTSA pre-crash typology (scenario_bank/README.md), and the actor-bound
story blocks of the sidecars that have one.

Fast tests: the README's typology table has one row per type 1..37, each naming bank scenarios that exist
or saying why the type is left out; every story block names actors the script names (``with name``) and
speaks the element vocabulary.

Slow tests (``-m slow``): the point of some typology scenarios, read off the trajectories with the
constant-speed ego (which never gets out of the way): the manoeuvre happens in front of the ego.
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow plain `pytest` from any folder
    sys.path.insert(0, str(ROOT))

from scenario_bank import BANK_DIR, list_scenarios  # noqa: E402
from scenario_bank.elements import ACTIONS, PARTICIPANTS, RELATIONS  # noqa: E402

README = ROOT / "scenario_bank" / "README.md"
NAMES = list_scenarios()
WITH_STORY = [n for n in NAMES if "story" in json.loads((BANK_DIR / n / "meta.json").read_text(encoding="utf-8"))]


def typology_rows():
    """``{type number: cell text}`` of the README's typology table."""
    rows = {}
    for line in README.read_text(encoding="utf-8").splitlines():
        match = re.match(r"^\| (\d+) \| [^|]+ \| (.+) \|$", line)
        if match:
            number = int(match.group(1))
            assert number not in rows, f"type {number} listed twice"
            rows[number] = match.group(2)
    return rows


def test_the_readme_lists_every_type_of_the_typology_once():
    assert sorted(typology_rows()) == list(range(1, 38))


def test_every_type_names_existing_scenarios_or_says_why_not():
    for number, cell in typology_rows().items():
        left_out = cell.startswith(("left out:", "not yet covered:"))
        named = re.findall(r"`([a-z0-9_]+)`", cell)
        if left_out:
            assert len(cell) > 40, f"type {number} says it is left out without saying why"
            # a left-out type may point at the scenarios nearest to it (and name other things in code style)
            named = [n for n in named if n.startswith(("highway_", "urban_"))]
        else:
            assert named, f"type {number} names no scenario: {cell}"
        for name in named:
            assert name in NAMES, f"type {number} names {name!r}, which is not a bank scenario"


def test_the_typology_scenarios_are_in_the_bank_listing():
    covered = {name for cell in typology_rows().values() if not cell.startswith(("left out", "not yet"))
               for name in re.findall(r"`([a-z0-9_]+)`", cell)}
    # every scenario with a story block was written for a type of the typology
    assert set(WITH_STORY) <= covered


@pytest.mark.parametrize("name", WITH_STORY)
def test_story_block_names_script_actors_in_the_vocabulary(name):
    meta = json.loads((BANK_DIR / name / "meta.json").read_text(encoding="utf-8"))
    script = (BANK_DIR / name / "scenario.scenic").read_text(encoding="utf-8")
    story = meta["story"]
    named = set(re.findall(r'with name "([^"]+)"', script))
    assert story["actors"] and set(story["actors"]) <= named, (story["actors"], named)
    assert all(kind in PARTICIPANTS and kind != "ego" for kind in story["actors"].values())
    assert story["steps"]
    for step in story["steps"]:
        assert step["actor"] in story["actors"]
        assert step["action"] in ACTIONS
        for relation, other in step.get("relations", []):
            assert relation in RELATIONS and other == "ego"
        assert step.get("within_s", 1.0) > 0
        # the element block states the same (by kind), so element-based search and metrics see the story
        kind = story["actors"][step["actor"]]
        assert [kind, step["action"]] in meta["elements"]["actions"]
