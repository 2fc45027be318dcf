"""A real loop folder moved (``mv``) while a round is under way resumes where it is: killed inside its mining run
(after the conversion's first bank entry), inside the control's DAgger fine-tuning (after its first checkpoint) and
inside the regression test's run (after its first episode), moved after each kill and resumed there, it finishes
with the report of a loop run in one go; and an inner run's refusal inside a loop gives the loop's advice."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from dv2s_gym.regress.store import RunStore
from policies.dagger_checkpoint import DAggerCheckpoint
from scenario_bank.bank import Bank
from scenario_bank.run_identity import RunIdentityError
from loop_helpers import run_loop

SETTINGS = dict(scenarios=["highway_lead_vehicle_brakes", "highway_truck_cut_in"], budget=16, fine_tune_steps=256,
                k_eval=2, regress_episodes=1, workers=2, n_envs=1, untouched_seeds=0, progress=False,
                log=lambda _: None)
"""The end-to-end test's tiny round (tests/test_loop_end_to_end.py) without the untouched set, one of whose scripts
samples other parameters from one run to the next with the same seeds (tests/test_behaviour_runs.py), so two runs
of it cannot be compared."""


class _Kill(BaseException):
    """Stands for the process being killed mid-step."""


def _kill_after(monkeypatch, owner: type, name: str, where) -> None:
    """``owner.name`` runs, then kills the process the first time ``where(self)`` holds."""
    real = getattr(owner, name)

    def killing(self, *args, **kwargs):
        value = real(self, *args, **kwargs)
        if where(self):
            monkeypatch.setattr(owner, name, real)
            raise _Kill()
        return value

    monkeypatch.setattr(owner, name, killing)


_KILLS = {
    "mining": (Bank, "add", lambda bank: Path(bank.root).name == "bank"),
    "control DAgger": (DAggerCheckpoint, "save", lambda checkpoint: checkpoint.folder.parent.name == "control"),
    "regression test": (RunStore, "append", lambda store: store.root.name == "regress"),
}


_RECORDS = ("loop.json", "settings.json", "run.json", "progress.json", "meta.json", "heldout.jsonl",
            "episodes.jsonl", "conversions.jsonl", "replays.jsonl", "results.jsonl")
"""The files of a loop folder that a resume reads: the runs' records, the bank entries' sidecars, the logs."""


def _comparable(report: dict, folder: Path) -> dict:
    """``report.json`` without the loop folder's path and the wall times (which differ from run to run)."""
    def strip(value):
        if isinstance(value, dict):
            return {key: strip(item) for key, item in value.items() if key not in ("timings", "seconds")}
        if isinstance(value, list):
            return [strip(item) for item in value]
        return value.replace(str(folder), "<loop>") if isinstance(value, str) else value
    return strip(report)


@pytest.mark.slow
def test_a_loop_killed_in_three_inner_runs_and_moved_after_each_finishes_as_a_run_in_one_go(tmp_path, monkeypatch):
    reference = run_loop("dv2s-ppo", out=tmp_path / "reference", **SETTINGS)
    expected = _comparable(json.loads(reference.paths["json"].read_text()), tmp_path / "reference")

    folder = tmp_path / "first"
    for number, (stage, (owner, name, where)) in enumerate(_KILLS.items(), start=1):
        _kill_after(monkeypatch, owner, name, where)
        with pytest.raises(_Kill):
            run_loop("dv2s-ppo", out=folder, **SETTINGS)
        moved = tmp_path / f"moved_{number}"
        shutil.move(folder, moved)
        folder = moved
        assert getattr(owner, name).__name__ != "killing", f"the loop did not reach the kill in {stage}"
    report = run_loop("dv2s-ppo", out=folder, **SETTINGS)
    got = _comparable(json.loads(report.paths["json"].read_text()), folder)
    # the control's DAgger went on from its checkpoint in the moved folder (the report says so), not from the start
    assert got["rounds"][0]["steps"]["control"].pop("resumed") == [
        {"from_iteration": 1, "steps_into_next": 0, "envs_reproduced": True}]
    assert expected["rounds"][0]["steps"]["control"].pop("resumed") == []
    for step, value in expected["rounds"][0]["steps"].items():  # step by step: a difference names its step
        assert got["rounds"][0]["steps"][step] == value, step
    assert got == expected
    # no record a resume reads names a place the folder was before (a report names where it was written)
    for path in folder.rglob("*"):
        if path.is_file() and path.name in _RECORDS:
            text = path.read_text(encoding="utf-8")
            for before in ("first", "moved_1", "moved_2"):
                assert str(tmp_path / before) not in text, path


def test_an_inner_run_refusing_to_resume_inside_a_loop_gives_the_loops_advice(tmp_path):
    loop = tmp_path / "loop"
    loop.mkdir()
    (loop / "loop.json").write_text(json.dumps({"schema": "dv2s-loop-state", "version": 2}))
    out = loop / "round_1" / "untouched" / "vs_start"
    RunStore(out, {"episodes": 1, "bank_dir": str(loop / "bank")}).open()
    assert json.loads((out / "run.json").read_text())["settings"]["bank_dir"] == "<loop>/bank"
    with pytest.raises(RunIdentityError) as refused:
        RunStore(out, {"episodes": 2, "bank_dir": str(loop / "bank")}).open()
    message = str(refused.value)
    assert "episodes: run has 1, asked 2" in message
    assert f"a step of the loop in {loop}" in message and f"dv2s loop --out {loop}" in message
    assert "choose another --out" not in message
