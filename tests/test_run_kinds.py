"""A run folder holds one kind of run: every run kind refuses an ``--out`` that holds another kind's run (its
reports would be written over the other's)."""

from __future__ import annotations

import json

import pytest

from cli_helpers import one_line_error, run
from scenario_bank.run_identity import RUN_KINDS, check_run_kind, record_format


def _write(folder, schema):
    file, _ = RUN_KINDS[schema]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / file).write_text(json.dumps({**record_format(schema, 1), "settings": {}}), encoding="utf-8")
    (folder / "report.json").write_text('{"kept": true}', encoding="utf-8")


@pytest.mark.parametrize("held", sorted(RUN_KINDS))
@pytest.mark.parametrize("asked", sorted(RUN_KINDS))
def test_a_folder_of_one_kind_refuses_a_run_of_another(tmp_path, held, asked):
    _write(tmp_path / "out", held)
    if held == asked:
        check_run_kind(tmp_path / "out", asked, error=ValueError)  # its own kind: the kind's own checks follow
        return
    with pytest.raises(ValueError, match=rf"holds {RUN_KINDS[held][1]} \(its {RUN_KINDS[held][0]}\), not "
                                         rf"{RUN_KINDS[asked][1]}: pass another --out"):
        check_run_kind(tmp_path / "out", asked, error=ValueError)


def test_each_run_kind_names_its_record_in_the_table():
    from dv2s_gym.loop.run import STATE_SCHEMA
    from dv2s_gym.mining.miner import SETTINGS_FILE, SETTINGS_SCHEMA
    from dv2s_gym.regress import store
    from policies.training import run_record

    assert RUN_KINDS[SETTINGS_SCHEMA][0] == SETTINGS_FILE and RUN_KINDS[STATE_SCHEMA][0] == "loop.json"
    assert RUN_KINDS[store._RUN_SCHEMA][0] == store.RUN_FILE and RUN_KINDS[run_record._RUN_SCHEMA][0] == "run.json"


@pytest.mark.parametrize("held, command", [
    ("dv2s-loop-state", ["mine", "--policy", "rule", "--scenarios", "highway_lead_vehicle_brakes", "--budget", "1",
                         "--workers", "1", "--no-convert", "--no-progress"]),
    ("dv2s-mine", ["regress", "--policy", "rule", "--baseline", "idm", "--scenarios", "highway_lead_vehicle_brakes",
                   "--episodes", "1", "--workers", "1", "--no-progress"]),
    ("dv2s-regress-run", ["loop", "--budget", "4", "--no-progress"]),
    ("dv2s-regress-run", ["train", "--algo", "ppo", "--scenarios", "highway_lead_vehicle_brakes", "--steps", "64",
                          "--resume"]),
])
def test_the_commands_refuse_another_kinds_folder_and_keep_its_reports(capsys, tmp_path, held, command):
    _write(tmp_path / "out", held)
    code, _, err = run(capsys, *command, "--out", tmp_path / "out")
    assert code == 2 and f"holds {RUN_KINDS[held][1]}" in one_line_error(err), err
    assert json.loads((tmp_path / "out" / "report.json").read_text()) == {"kept": True}
