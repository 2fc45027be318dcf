"""A run folder or report that lacks what this dv2s-gym writes is refused in one line naming it and the fix
(rerun with a new ``--out``); no older layout is read on."""

from __future__ import annotations

import json

import pytest

from loop_helpers import run_loop
from dv2s_gym.mining.loop_settings import LoopError
from dv2s_gym.regress.errors import ReportMismatchError
from dv2s_gym.regress.report import SCHEMA, SCHEMA_VERSION, load_report

_ERRORED = {"episodes": 1, "scenarios": {"s": 1}, "messages": {"s": [{"message": "boom", "count": 1}]},
            "examples": {"s": "boom"}}


def _loop_json(tmp_path, settings, steps=None):
    folder = tmp_path / "loop"
    folder.mkdir()
    rounds = [] if steps is None else [{"round": 1, "steps": steps, "timings": {}}]
    (folder / "loop.json").write_text(json.dumps({"settings": settings, "start": None, "rounds": rounds}))
    return folder


@pytest.mark.parametrize("settings, steps, what", [
    ({}, None, "records holdout_by None, not 'family'"),
    ({"holdout_by": "cluster"}, None, "records holdout_by 'cluster', not 'family'"),
    ({"holdout_by": "family"}, {"mine": {"episodes": 3, "errors": 1}}, "round 1's mining step records no errored"),
    ({"holdout_by": "family"}, {"mine": {"errored": {"episodes": 1, "scenarios": {"s": 1}, "examples": {"s": "x"}}}},
     "round 1's 'mine' step records its errored episodes without every message"),
    ({"holdout_by": "family"}, {"mine": {"errored": _ERRORED}, "untouched": {"errored": {"fine_tuned": {
        **_ERRORED, "unlisted": {"s": {"messages": 3, "episodes": 5}}}}}},
     "round 1's 'untouched' step records its errored episodes without every message"),
    ({"holdout_by": "family"}, {"after": {"pairs": 1, "heldout_families": 1, "table": {"after_only": 1}}},
     "round 1's held-out step records no held-out tests with their families' harm check"),
    ({"holdout_by": "family"}, {"after": {"pairs": 9, "significantly_worse": {"start": {"worse": False}}}},
     "round 1's held-out step records no held-out tests with their families' harm check"),
])
def test_a_loop_folder_of_an_older_layout_is_refused_in_one_line(tmp_path, settings, steps, what):
    folder = _loop_json(tmp_path, settings, steps)
    with pytest.raises(LoopError) as error:
        run_loop("dv2s-ppo", out=folder, budget=8, log=lambda _: None, progress=False)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{folder} was written by an older dv2s-gym (")
    assert what in message and message.endswith("rerun with a new --out")


def test_a_regress_report_without_its_failure_kinds_is_refused(tmp_path):
    path = tmp_path / "report.json"
    report = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "settings": {"seed": 0, "episodes": 2}}
    path.write_text(json.dumps(report))
    with pytest.raises(ReportMismatchError) as error:
        load_report(path)
    message = str(error.value)
    assert "\n" not in message and str(path) in message and "written by an older dv2s-gym" in message
    assert "rerun that `dv2s regress` command with a new --out" in message
    path.write_text(json.dumps({**report, "settings": {**report["settings"], "failure": ["collision"]}}))
    assert load_report(path)["settings"]["failure"] == ["collision"]


def test_the_older_paths_are_gone():
    """No split by cluster, no failure kinds assumed for a report that names none, no anonymous error counts."""
    from dv2s_gym.mining import errored, split
    from dv2s_gym.regress import failures
    from scenario_bank.failure_types import FailureType

    assert not hasattr(split, "split_by_cluster") and not hasattr(failures, "FAILURE_BEFORE_CHOICE")
    assert "counted_before_choice" not in FailureType.__dataclass_fields__
    merged = errored.merged_messages([_ERRORED, _ERRORED])
    assert merged == {"s": [{"message": "boom", "count": 2}]}
