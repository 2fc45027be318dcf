"""The resume check every resumable run shares (`scenario_bank.run_identity`)."""

from __future__ import annotations

import dataclasses
from typing import Optional, Tuple

import pytest

from scenario_bank.errors import DV2SError
from scenario_bank.run_identity import (RunIdentityError, check_format, check_identity, differing, identity_of,
                                        record_format, recorded_settings, setting)


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


def test_a_setting_one_side_lacks_is_none():
    keys = ("seed", "control")
    assert differing({"seed": 1}, {"seed": 1, "control": False}, keys) == ["control"]
    assert differing({"seed": 1}, {"seed": 1}, keys) == []


def test_many_differences_are_counted_past_the_first_three_and_notes_say_why():
    keys = tuple("abcde")
    with pytest.raises(RunIdentityError, match=r"and 2 more\); start over") as error:
        check_identity(dict.fromkeys(keys, 0), dict.fromkeys(keys, 1), keys, run="run", fix="start over",
                       notes={"a": " (the file changed)"})
    assert "a: run has 0, asked 1 (the file changed)" in str(error.value) and len(error.value.differences) == 5


@dataclasses.dataclass(frozen=True)
class _Settings:
    seed: int = 0
    threshold: float = 1
    names: Tuple[str, ...] = ("a",)
    limit: Optional[int] = None
    bank: Optional[str] = setting(None, record=lambda path: path and path.upper())
    workers: int = setting(2, resume=False, record=False)


def test_a_settings_class_is_recorded_as_json_values():
    recorded = recorded_settings(_Settings(seed=1, threshold=2, bank="b"))
    assert recorded == {"seed": 1, "threshold": 2.0, "names": ["a"], "limit": None, "bank": "B"}


def test_a_setting_recorded_as_null_stays_null():
    with pytest.raises(RunIdentityError, match=r"\(threshold: run has None, asked 1.0\)"):
        check_identity({"threshold": None}, {"threshold": 1.0}, ("threshold",), run="r", fix="f")
    check_identity({"limit": None}, {}, ("limit",), run="r", fix="f")  # left out: None too


class _FormatError(DV2SError):
    pass


def test_a_record_of_this_format_passes():
    record = {**record_format("dv2s-x", 3), "settings": {}}
    assert record_format("dv2s-x", 3) == {"schema": "dv2s-x", "version": 3}
    check_format(record, "dv2s-x", 3, folder="out", what="an x run", file="run.json", error=_FormatError)


@pytest.mark.parametrize("record, found", [
    ({"schema": "dv2s-x", "version": 2}, "format 2"),
    ({"schema": "dv2s-x", "version": 4}, "format 4"),
    ({"schema": "dv2s-x"}, "no format"),
    ({"settings": {}}, "no format"),
    ({"schema": "dv2s-y", "version": 3}, "no format"),
    ({"schema": "dv2s-x", "version": "3"}, "no format"),
    ({"schema": "dv2s-x", "version": True}, "no format"),
    ([], "no format"),
])
def test_a_record_of_another_format_or_none_is_refused_in_one_line(record, found):
    with pytest.raises(_FormatError) as error:
        check_format(record, "dv2s-x", 3, folder="out", what="an x run", file="run.json", error=_FormatError)
    assert str(error.value) == (f"out holds an x run written by another version of dv2s-gym (its run.json records "
                                f"{found}, this dv2s-gym reads format 3); start a new --out folder")
