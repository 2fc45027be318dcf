"""The resume check every resumable run shares (`scenario_bank.run_identity`)."""

from __future__ import annotations

import pytest

from scenario_bank.errors import DV2SError
from scenario_bank.run_identity import RunIdentityError, check_identity, differing, identity_of


def test_the_same_settings_pass_and_json_round_trips_count_as_the_same():
    recorded = identity_of({"seed": 1, "scenarios": ("a", "b"), "rate": 1, "extra": "x"}, ("seed", "scenarios", "rate"))
    assert recorded == {"seed": 1, "scenarios": ["a", "b"], "rate": 1}
    check_identity(recorded, {"seed": 1, "scenarios": ("a", "b"), "rate": 1.0}, ("seed", "scenarios", "rate"),
                   run="out holds a run", fix="resume with its settings")


def test_every_difference_is_named_with_both_values_and_the_fix():
    with pytest.raises(RunIdentityError) as error:
        check_identity({"seed": 1, "sampler": "halton", "budget": 4}, {"seed": 2, "sampler": "random", "budget": 4},
                       ("seed", "sampler", "budget"), run="out holds a mining run", fix="pass another --out")
    message = str(error.value)
    assert message == ("out holds a mining run with other settings (seed: run has 1, asked 2; sampler: run has "
                       "'halton', asked 'random'); pass another --out")
    assert error.value.differences == [("seed", 1, 2), ("sampler", "halton", "random")]
    assert isinstance(error.value, DV2SError) and isinstance(error.value, ValueError)


def test_a_setting_the_run_did_not_record_differs_from_any_asked_value():
    keys = ("seed", "control")
    assert differing({"seed": 1}, {"seed": 1, "control": False}, keys) == ["control"]
    assert differing({"seed": 1}, {"seed": 1}, keys) == []


def test_many_differences_are_counted_past_the_first_three_and_notes_say_why():
    keys = tuple("abcde")
    with pytest.raises(RunIdentityError, match=r"and 2 more\); start over") as error:
        check_identity(dict.fromkeys(keys, 0), dict.fromkeys(keys, 1), keys, run="run", fix="start over",
                       notes={"a": " (the file changed)"})
    assert "a: run has 0, asked 1 (the file changed)" in str(error.value) and len(error.value.differences) == 5
