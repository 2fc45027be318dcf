"""A run folder moved (``mv``) elsewhere resumes where it is, for every run kind whose record names a path inside
it: a mining run, a regression run, a training run and a DAgger fine-tuning, each with its bank (and the regression
run its candidate checkpoint) inside its folder. The record names those paths relative to the folder
(:mod:`scenario_bank.run_paths`) and a path outside it as it is. A moved loop: tests/test_loop_moved.py."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from dv2s_gym.mining.settings import read_run_settings
from mining_helpers import mine, mine_killed_after
from regress_call import run_regression
from fine_tune_helpers import dagger_fine_tune
from policies.dagger_checkpoint import CHECKPOINT_DIR, DAggerCheckpoint
from policies.registry import SHIPPED_CHECKPOINT
from policies.training import TrainConfig, run_settings, train
from scenario_bank.bank import Bank
from scenario_bank.run_paths import as_read, loop_folder, read_paths, record_paths, resume_fix

SCENARIO = "highway_lead_vehicle_brakes"


def _bank_in(folder: Path) -> Path:
    bank = folder / "bank"
    Bank().copy_to(bank)
    return bank


def _move(folder: Path, to: Path) -> Path:
    shutil.move(str(folder), str(to))
    assert not folder.exists()
    return to


def test_paths_inside_the_run_or_its_loop_folder_are_written_after_a_mark_and_read_back_where_they_are(tmp_path):
    loop = tmp_path / "loop"
    run = loop / "round_1" / "mine"
    run.mkdir(parents=True)
    assert loop_folder(run) is None  # no loop.json yet: not a loop folder
    (loop / "loop.json").write_text(json.dumps({"schema": "dv2s-loop-state", "version": 2}))
    assert loop_folder(run) == loop
    value = {"bank_dir": str(loop / "bank"), "policy": f"ppo:{loop}/round_1/policy/model.zip",
             f"checkpoint {loop}/round_1/policy/model.zip (SHA-256)": "ab", "trace": str(run / "traces" / "0.json"),
             "elsewhere": str(tmp_path / "loop2" / "bank"), "number": 3}
    written = record_paths(value, run)
    assert written == {"bank_dir": "<loop>/bank", "policy": "ppo:<loop>/round_1/policy/model.zip",
                       "checkpoint <loop>/round_1/policy/model.zip (SHA-256)": "ab", "trace": "<run>/traces/0.json",
                       "elsewhere": str(tmp_path / "loop2" / "bank"), "number": 3}
    assert read_paths(written, run) == value
    moved = _move(loop, tmp_path / "there")
    assert read_paths(written, moved / "round_1" / "mine")["bank_dir"] == str(moved / "bank")
    assert as_read(f"ppo:{moved}/round_1/policy/model.zip", moved / "round_1" / "mine") == \
        f"ppo:{moved}/round_1/policy/model.zip"
    assert resume_fix(tmp_path / "alone", "pass another --out") == "pass another --out"
    assert f"a step of the loop in {moved}" in resume_fix(moved / "round_1" / "mine", "pass another --out")


@pytest.mark.slow
def test_a_moved_mining_run_resumes_where_it_is(tmp_path, monkeypatch):
    out = tmp_path / "mine"
    out.mkdir()
    run = dict(scenarios=(SCENARIO,), seed=0, convert=False, workers=1, progress=False, reports=False)
    mine_killed_after("rule", out, 2, monkeypatch, bank_dir=str(_bank_in(out)), budget=4, **run)
    assert json.loads((out / "settings.json").read_text())["bank_dir"] == "<run>/bank"
    before = (out / "episodes.jsonl").read_text().splitlines()
    moved = _move(out, tmp_path / "moved")
    resumed = mine("rule", out=moved, bank_dir=str(moved / "bank"), budget=4, **run)
    assert [r.index for r in resumed.records] == [0, 1, 2, 3]
    assert (moved / "episodes.jsonl").read_text().splitlines()[:len(before)] == before
    assert read_run_settings(moved).bank_dir == str(moved / "bank")


@pytest.mark.slow
def test_a_moved_regression_run_resumes_where_it_is(tmp_path):
    out = tmp_path / "regress"
    bank = _bank_in(out)
    (out / "policy").mkdir()
    for name in ("model.zip", "model_card.json"):
        shutil.copyfile(SHIPPED_CHECKPOINT.parent / name, out / "policy" / name)
    run = dict(scenarios=[SCENARIO], episodes=2, workers=1, progress=False, clips=False)
    first = run_regression(f"ppo:{out}/policy/model.zip", "rule", out_dir=out, bank_dir=str(bank), **run)
    recorded = json.loads((out / "run.json").read_text())["settings"]
    assert recorded["candidate"] == "ppo:<run>/policy/model.zip"
    assert "checkpoint <run>/policy/model.zip (SHA-256)" in recorded["policy_fingerprint"]
    results = (out / "results.jsonl").read_text().splitlines()
    (out / "results.jsonl").write_text("\n".join(results[:1]) + "\n")  # a run killed after its first episode
    moved = _move(out, tmp_path / "moved")
    again = run_regression(f"ppo:{moved}/policy/model.zip", "rule", out_dir=moved, bank_dir=str(moved / "bank"),
                           **run)
    assert (moved / "results.jsonl").read_text().splitlines()[0] == results[0]
    assert again.verdict == first.verdict and again.overall.to_dict() == first.overall.to_dict()


def test_a_moved_training_run_resumes_where_it_is(tmp_path):
    out = tmp_path / "train"
    out.mkdir()
    config = TrainConfig(out=str(out), algo="ppo", scenarios=(SCENARIO,), bank_dir=str(_bank_in(out)), steps=64,
                         n_envs=1, eval_freq=0, card_seeds=0, checkpoint_freq=32, progress_bar=False,
                         vec_env="dummy", hyperparameters={"n_steps": 32, "batch_size": 32, "n_epochs": 1})
    train(config, log=lambda _: None)
    assert json.loads((out / "run.json").read_text())["config"]["bank_dir"] == "<run>/bank"
    moved = _move(out, tmp_path / "moved")
    lines = []
    card = train(run_settings(moved, {}, resume=True), resume=True, log=lines.append)
    assert any("nothing to train" in line for line in lines) and card.training["steps"] >= 64
    assert json.loads((moved / "run.json").read_text())["config"]["bank_dir"] == "<run>/bank"


@pytest.mark.slow
def test_a_moved_dagger_fine_tuning_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    out = tmp_path / "dagger"
    bank = _bank_in(out)
    run = dict(steps=200, weights={SCENARIO: 1.0}, seed=3, n_envs=1, vec_env="dummy", iterations=2, epochs=1,
               batch_size=64, progress_bar=False)
    real = DAggerCheckpoint.save

    def killed(self, *args, **kwargs):  # the first iteration committed, then the process is killed
        real(self, *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(DAggerCheckpoint, "save", killed)
    with pytest.raises(KeyboardInterrupt):
        dagger_fine_tune("dv2s-ppo", out=out, bank_dir=str(bank), log=lambda _: None, **run)
    monkeypatch.undo()
    progress = json.loads((out / CHECKPOINT_DIR / "progress.json").read_text())
    assert progress["identity"]["bank_dir"] == "<run>/bank" and progress["iteration"] == 1
    moved = _move(out, tmp_path / "moved")
    lines = []
    dagger_fine_tune("dv2s-ppo", out=moved, bank_dir=str(moved / "bank"), log=lines.append, **run)
    assert lines[0].startswith("DAgger: resumed from iteration 1 of 2")
    assert (moved / "model.zip").is_file() and not (moved / CHECKPOINT_DIR).exists()
