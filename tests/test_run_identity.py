"""The resume check every resumable run shares (`scenario_bank.run_identity`)."""

from __future__ import annotations

import dataclasses
from typing import Optional, Tuple

import pytest

from scenario_bank.errors import DV2SError
from scenario_bank.run_identity import (RunIdentityError, check_identity, differing, identity_of, setting,
                                        setting_defaults)


def test_the_same_settings_pass_and_json_round_trips_count_as_the_same():
    recorded = identity_of({"seed": 1, "scenarios": ("a", "b"), "rate": 1, "extra": "x"}, ("seed", "scenarios", "rate"))
    assert recorded == {"seed": 1, "scenarios": ["a", "b"], "rate": 1}
    check_identity(recorded, {"seed": 1, "scenarios": ("a", "b"), "rate": 1.0}, ("seed", "scenarios", "rate"),
                   run="out holds a run", fix="resume with its settings", defaults=None)


def test_every_difference_is_named_with_both_values_and_the_fix():
    with pytest.raises(RunIdentityError) as error:
        check_identity({"seed": 1, "sampler": "halton", "budget": 4}, {"seed": 2, "sampler": "random", "budget": 4},
                       ("seed", "sampler", "budget"), run="out holds a mining run", fix="pass another --out",
                       defaults=None)
    message = str(error.value)
    assert message == ("out holds a mining run with other settings (seed: run has 1, asked 2; sampler: run has "
                       "'halton', asked 'random'); pass another --out")
    assert error.value.differences == [("seed", 1, 2), ("sampler", "halton", "random")]
    assert isinstance(error.value, DV2SError) and isinstance(error.value, ValueError)


def test_a_setting_without_a_default_the_run_did_not_record_differs_from_any_asked_value():
    keys = ("seed", "control")
    assert differing({"seed": 1}, {"seed": 1, "control": False}, keys) == ["control"]
    assert differing({"seed": 1}, {"seed": 1}, keys) == []


def test_many_differences_are_counted_past_the_first_three_and_notes_say_why():
    keys = tuple("abcde")
    with pytest.raises(RunIdentityError, match=r"and 2 more\); start over") as error:
        check_identity(dict.fromkeys(keys, 0), dict.fromkeys(keys, 1), keys, run="run", fix="start over",
                       notes={"a": " (the file changed)"}, defaults=None)
    assert "a: run has 0, asked 1 (the file changed)" in str(error.value) and len(error.value.differences) == 5


@dataclasses.dataclass(frozen=True)
class _Settings:
    seed: int = 0
    threshold: float = 1
    names: Tuple[str, ...] = ("a",)
    limit: Optional[int] = None
    bank: Optional[str] = setting(None, record=lambda path: path and path.upper())
    workers: int = setting(2, resume=False, record=False)


def test_a_settings_classes_defaults_are_its_recorded_values():
    assert setting_defaults(_Settings) == {"seed": 0, "threshold": 1.0, "names": ["a"], "limit": None, "bank": None}
    assert setting_defaults(_Settings, ("seed", "workers")) == {"seed": 0}


@pytest.mark.parametrize("defaults", [_Settings, {"threshold": 1.0}], ids=["class", "mapping"])
def test_a_setting_the_run_did_not_record_is_its_default(defaults):
    keys = ("seed", "threshold")
    check_identity({"seed": 1}, {"seed": 1, "threshold": 1.0}, keys, run="out holds a run", fix="f", defaults=defaults)
    assert differing({"seed": 1}, {"seed": 1}, keys, defaults=defaults) == []  # absent on both sides: the same
    with pytest.raises(RunIdentityError) as error:
        check_identity({"seed": 1}, {"seed": 1, "threshold": 2.5}, keys, run="out holds a run", fix="f",
                       defaults=defaults)
    assert str(error.value) == ("out holds a run with other settings (threshold: run has 1.0 (not recorded: the "
                                "default), asked 2.5); f")
    assert error.value.differences == [("threshold", 1.0, 2.5)]


def test_a_setting_recorded_as_null_stays_null():
    with pytest.raises(RunIdentityError, match=r"\(threshold: run has None, asked 1.0\)"):
        check_identity({"threshold": None}, {"threshold": 1.0}, ("threshold",), run="r", fix="f", defaults=_Settings)
