"""The evaluation sets shipped with dv2s-gym, named on the command line: ``dv2s eval STAGE --set NAME`` reads the
set's folder from the package (not a checkout path), a bad name or a folder given with a set is refused, and only
the in-house set ships (the external one lives beside its builder under bench/)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dv2s_gym.cli import main
from dv2s_gym.pipeline.evaluate import EVALSET_DIR, EVALSETS, collect_items, evalset_folder
from scenario_bank.errors import SettingError

ROOT = Path(__file__).resolve().parents[1]


def test_every_named_set_is_a_labeled_folder_in_the_package():
    assert evalset_folder("in-house") == EVALSET_DIR
    for name in EVALSETS:
        folder = evalset_folder(name)
        assert folder.is_relative_to(ROOT / "dv2s_gym")
        assert collect_items(folder, unlabeled_descriptions=True), name


def test_an_unknown_set_names_the_shipped_ones():
    with pytest.raises(SettingError, match="unknown evaluation set 'external'; the shipped sets are in-house, "
                                           "in-house-descriptions"):
        evalset_folder("external")


def test_the_command_line_offers_the_named_sets(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["eval", "dra", "--set", "bogus"])
    assert exit_.value.code == 2
    assert "choose from 'in-house', 'in-house-descriptions'" in capsys.readouterr().err
    assert main(["eval", "dra", "some/folder", "--set", "in-house"]) == 2
    assert "give a labeled folder or --set in-house, not both" in capsys.readouterr().err


def test_only_the_in_house_set_is_package_data():
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    data = re.search(r'^"dv2s_gym" = \[(.*?)\]$', text, re.M | re.S).group(1)
    assert '"evalset/*.webm"' in data and '"evalset/descriptions/*.txt"' in data
    assert "highway_env" not in data
    assert not (ROOT / "dv2s_gym" / "evalset_highway_env").exists()
