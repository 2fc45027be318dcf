"""``dv2s regress`` on a bank holding a scenario the package does not ship (imported, generated or mined: it runs
only in the jail) refuses to start where the jail cannot work, in one line with the jail's reason and fix, before
any episode; a run on shipped scenarios alone needs no jail and runs as before."""

from __future__ import annotations

from pathlib import Path

import pytest

from dv2s_gym.cli import main
from scenario_bank.bank import Bank, Sidecar
from scenario_bank.jail import bwrap, process

SCENARIO = "highway_lead_vehicle_brakes"
QUICK = '{"duration": 2}'
FAILURE = "collision,off_road"  # no stall: the episodes are too short for one


def _hide_code(monkeypatch) -> None:
    """The checkout as if it lay under /tmp, which the jail replaces with an empty folder of its own."""
    monkeypatch.setattr(bwrap, "CODE_ROOT", Path("/tmp/clone"))
    monkeypatch.setattr(bwrap, "bwrap_path", lambda: "/usr/bin/bwrap")
    monkeypatch.setattr(process, "_STATUS", {})


def _user_bank(folder: Path) -> Path:
    """A bank with one scenario of the user's: a shipped script with a line of its own, so no longer a shipped one."""
    script = Bank(None).get(SCENARIO).script + "\n# the user's own copy\n"
    Bank(folder).add(script, Sidecar(description="A lead vehicle brakes hard ahead of the ego.", map="highway_straight",
                                     name="user_lead_brakes", tags=["user"]))
    return folder


def test_a_bank_with_an_untrusted_scenario_is_refused_before_any_episode_where_the_jail_cannot_start(
        monkeypatch, tmp_path, capsys):
    bank = _user_bank(tmp_path / "bank")  # admitted while the jail works
    _hide_code(monkeypatch)
    out = tmp_path / "out"
    code = main(["regress", "--policy", "rule", "--baseline", "keep_lane", "--bank", str(bank), "--episodes", "2",
                 "--config", QUICK, "--failure", FAILURE, "--workers", "1", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err  # one line, not one error per episode
    assert "scenario 'user_lead_brakes'" in lines[0] and "runs only in the jail" in lines[0]
    assert "/tmp/clone is under /tmp" in lines[0] and "outside /tmp" in lines[0]  # the jail's reason and fix
    assert not (out / "results.jsonl").exists() or not (out / "results.jsonl").read_text().strip()


def test_a_run_on_shipped_scenarios_alone_needs_no_jail(monkeypatch, tmp_path, capsys):
    _hide_code(monkeypatch)
    out = tmp_path / "out"
    code = main(["regress", "--policy", "rule", "--scenarios", SCENARIO, "--episodes", "1", "--config", QUICK,
                 "--failure", FAILURE, "--workers", "1", "--no-progress", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "jail" not in captured.err and (out / "report.json").is_file()
