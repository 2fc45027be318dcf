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


def _bank(tmp_path):
    bank = Bank(tmp_path / "bank")
    bank.add(_SCRIPT.format(low=8, high=160), "a stopped car, wide gap")
    bank.add(_SCRIPT.format(low=9, high=150), "a stopped car, narrower gap")
    bank.add(_SCRIPT.format(low=300, high=400), "a stopped car far ahead")
    return bank


def test_near_duplicate_scripts_are_one_family(tmp_path):
    bank = _bank(tmp_path)
    wide, narrow, far = (bank.find_near_duplicate(_SCRIPT.format(low=lo, high=hi), e.elements, e.map)[0]
                         for (lo, hi), e in zip(((8, 160), (9, 150), (300, 400)), sorted(bank, key=lambda e: e.name)))
    families = content_families(bank)
    assert families[wide] == families[narrow]
    assert families[far] == far != families[wide]
    assert scenario_family(wide, str(bank.root)) == scenario_family(narrow, str(bank.root))


def test_the_loop_split_keeps_a_twin_with_its_held_out_family(tmp_path):
    bank = _bank(tmp_path)
    names = sorted(e.name for e in bank)
    families = content_families(bank)
    twins = sorted(n for n in names if families[n] != n or sum(v == n for v in families.values()) > 1)
    assert len(twins) == 2
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
        bank.add(_SCRIPT.format(low=500, high=600), "a stopped car very far ahead")
