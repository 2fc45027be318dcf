"""Near-duplicate bank scripts are one scenario family: the loop never holds out one and fine-tunes on its twin,
and mining counts them as one family."""

from __future__ import annotations

import warnings

import pytest

from dv2s_gym.mining.family import scenario_family
from dv2s_gym.loop.mined import with_parents
from dv2s_gym.loop.split import family_of, split_by_family
from scenario_bank.bank import Bank
from scenario_bank.errors import NearDuplicateWarning
from scenario_bank.families import content_families
from cli_helpers import run

_SCRIPT = '''"""A car stands still ahead of the ego."""
param map = 'highway_straight'
model scenic.domains.driving.model

param ego_speed = Range(20, 28)
param stop_gap = Range({low}, {high})

lane = Uniform(*network.lanes)
ego = new Car on lane.centerline, with speed globalParameters.ego_speed
blocker = new Car following roadDirection from ego for globalParameters.stop_gap, with speed 0
'''


_OTHER = '''"""A slow car ahead and a car beside the ego."""
param map = 'highway_onramp'
model scenic.domains.driving.model

param ego_speed = Range(20, 28)
param lead_gap = Range(15, 40)
param lead_speed = Range(5, 10)

lane = Uniform(*network.lanes)
ego = new Car on lane.centerline, with speed globalParameters.ego_speed
lead = new Car following roadDirection from ego for globalParameters.lead_gap, with speed globalParameters.lead_speed
side = new Car left of ego by 3.5, with speed globalParameters.ego_speed
'''


def _bank(tmp_path):
    bank = Bank(tmp_path / "bank")
    bank.add(_SCRIPT.format(low=8, high=160), "a stopped car, wide gap")
    bank.add(_SCRIPT.format(low=9, high=150), "a stopped car, narrower gap")
    bank.add(_OTHER, "a slow car ahead, a car beside")
    return bank


def _stopped(bank):
    """The two stopped-car entries' names (wide gap, narrower gap) and the slow car's."""
    wide, narrow = (bank.find_near_duplicate(_SCRIPT.format(low=lo, high=hi), e.elements, e.map)[0]
                    for (lo, hi), e in zip(((8, 160), (9, 150)), sorted(bank, key=lambda e: e.name)))
    return wide, narrow, next(e.name for e in bank if e.name not in (wide, narrow))


def test_near_duplicate_scripts_are_one_family(tmp_path):
    bank = _bank(tmp_path)
    wide, narrow, other = _stopped(bank)
    families = content_families(bank)
    assert families[wide] == families[narrow]
    assert families[other] == other != families[wide]
    assert scenario_family(wide, str(bank.root)) == scenario_family(narrow, str(bank.root))


def test_a_near_copy_is_one_family_however_far_its_moved_range_lies(tmp_path):
    """The same program with one range moved where the others' never reach (one line of code apart) plays the same
    story: one family with them, and adding it warns naming both."""
    bank = _bank(tmp_path)
    wide, narrow, other = _stopped(bank)
    with pytest.warns(NearDuplicateWarning) as caught:
        far = bank.add(_SCRIPT.format(low=300, high=400), "a stopped car far ahead")
    assert sorted(caught[0].message.twins) == sorted([wide, narrow])
    families = content_families(bank)
    assert families[far.name] == families[wide] == families[narrow] != families[other]


def test_the_same_program_with_other_elements_declared_is_one_family():
    from types import SimpleNamespace

    from scenario_bank.families import twins

    script = _SCRIPT.format(low=8, high=160)
    plain = SimpleNamespace(elements={"actors": ["car"]}, map="highway_straight")
    declared = SimpleNamespace(elements={"actors": ["car"], "relations": [["car", "left_of", "ego"]]},
                               map="highway_straight")
    commented = script.replace("A car stands still ahead of the ego.", "The same scene, another docstring.")
    commented = commented.replace("lane = Uniform", "# a comment of its own\nlane = Uniform")
    assert twins(plain, script, declared, commented)  # not one line of code differs
    assert not twins(plain, script, declared, _OTHER)


def test_the_loop_split_keeps_a_twin_with_its_held_out_family(tmp_path):
    bank = _bank(tmp_path)
    names = sorted(e.name for e in bank)
    families = content_families(bank)
    twins = sorted(n for n in names if families[n] != n or sum(v == n for v in families.values()) > 1)
    assert len(twins) == 2  # the two stopped-car scripts; the slow car is its own family
    kept = [{"scenario": f"mined_{n}", "cluster": f"{n}/collision/x", "parent": n} for n in names]
    entries = with_parents(kept, str(bank.root))
    for seed in range(6):
        split = split_by_family(entries, 0.5, seed=seed)
        sides = {e.to_dict()["parent"]: e.to_dict()["scenario"] in split.held_out for e in entries}
        twin_sides = {e.to_dict()["scenario"] in split.held_out for e in entries if family_of(e) == families[twins[0]]}
        assert len(twin_sides) == 1, (seed, sides)


def test_bank_add_warns_of_a_near_duplicate_naming_it(tmp_path, capsys):
    bank = _bank(tmp_path)
    path = tmp_path / "twin.scenic"
    path.write_text(_SCRIPT.format(low=10, high=140))
    code, _, err = run(capsys, "bank", "add", path, "--description", "a stopped car, gap 10 to 140",
                       "--bank", bank.root)
    assert code == 0
    warnings = [line for line in err.splitlines() if "near-duplicate of bank entry" in line]
    assert len(warnings) == 2 and "one scenario family" in warnings[0]


def test_bank_add_in_python_warns_of_a_near_duplicate_naming_it(tmp_path):
    bank = _bank(tmp_path)
    with pytest.warns(NearDuplicateWarning) as caught:
        entry = bank.add(_SCRIPT.format(low=10, high=140), "a stopped car, gap 10 to 140")
    warning = caught[0].message
    assert warning.name == entry.name and len(warning.twins) == 2 and "one scenario family" in str(warning)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NearDuplicateWarning)
        bank.add(_OTHER.replace("side = new Car left of ego by 3.5, with speed globalParameters.ego_speed\n", "")
                 .replace("lead_speed = Range(5, 10)", "lead_speed = Range(0, 3)")
                 + "behind = new Car following roadDirection from ego for -20\n"
                 + "far = new Car following roadDirection from ego for 80, with speed 25\n",
                 "a nearly stopped car ahead, cars behind and far ahead")
