"""A missing optional dependency is named, with the extra that installs it, in one message (scenario_bank.extras):
the command line's and the policy registry's say it alike, and no other module spells the install command."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from dv2s_gym.cli.errors import EXTRA_OF_MODULE, error_line, missing_extra
from policies.registry import PolicyError, load_policy
from scenario_bank.extras import extra_of, missing_extra_message

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenario_bank", "envs", "policies", "dv2s_gym")
SOURCE_OF_TRUTH = ROOT / "scenario_bank" / "extras.py"


def test_each_optional_module_has_the_extra_of_pyproject_that_installs_it():
    extras = re.search(r"^\[project\.optional-dependencies\]\n(.*?)^\[", (ROOT / "pyproject.toml").read_text(),
                       re.M | re.S).group(1)
    defined = set(re.findall(r"^(\w+) = \[", extras, re.M))
    assert set(EXTRA_OF_MODULE.values()) <= defined
    assert extra_of("stable_baselines3.common.policies") == "rl" and extra_of("yaml") == ""
    with pytest.raises(ValueError, match="'yaml' is no optional dependency"):
        missing_extra_message("yaml")


def test_the_command_line_names_the_missing_module_and_its_extra():
    error = ModuleNotFoundError("No module named 'verifai'", name="verifai.samplers")
    assert missing_extra(error) == "mining"
    assert error_line(error) == missing_extra_message("verifai") == (
        "this needs verifai, which is not installed: pip install 'dv2s-gym[mining]' (scripts/setup.sh installs "
        "every extra)")


def test_the_policy_registry_says_it_in_the_same_words(tmp_path, monkeypatch):
    checkpoint = tmp_path / "model.zip"
    checkpoint.write_bytes(b"not read: stable-baselines3 is missing first")
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # as if the rl extra were not installed
    with pytest.raises(PolicyError) as raised:
        load_policy(str(checkpoint))
    assert str(raised.value) == missing_extra_message("stable_baselines3", "loading SB3 checkpoints") == (
        "loading SB3 checkpoints needs stable_baselines3, which is not installed: pip install 'dv2s-gym[rl]' "
        "(scripts/setup.sh installs every extra)")
    assert error_line(raised.value) == str(raised.value)  # the command line prints it as it is


def test_no_module_but_the_source_of_truth_spells_the_install_command_of_an_extra():
    found = [f"{path.relative_to(ROOT)}:{number}" for package in PACKAGES
             for path in sorted((ROOT / package).rglob("*.py")) if path != SOURCE_OF_TRUTH
             for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if "dv2s-gym[" in line]
    assert not found, "install an extra through scenario_bank.extras.missing_extra_message:\n" + "\n".join(found)
