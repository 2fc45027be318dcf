"""A DAgger checkpoint records the code it runs and its reference driver's fingerprint
(:func:`policies.dagger_checkpoint.run_identity`), and a resume checks both as every resumable run does: a reference
driver edited or replaced since is refused naming it, and so is other code; an unchanged one resumes; a checkpoint
of the earlier format (without them) is refused with the fix."""

from __future__ import annotations

import json

import pytest

from policies.dagger_checkpoint import (CHECKPOINT_DIR, REFERENCE_FINGERPRINT, DAggerCheckpoint, DAggerResumeError,
                                        run_identity)
from policies.dagger_config import DaggerConfig
from policies.registry import SHIPPED_CHECKPOINT
from policies.run_identity import CODE_IDENTITY
from policies.training import TrainConfig
from scenario_bank.atomic import file_sha256
from scenario_bank.run_identity import RunIdentityError

SCENARIO = "highway_lead_vehicle_brakes"
DRIVER = "from policies.rule_based import CautiousDriver as Driver\n"


def _identity(out, reference):
    config = TrainConfig.fine_tuning(out, steps=10, weights={SCENARIO: 1.0})
    return run_identity(source="dv2s-ppo", source_checkpoint=SHIPPED_CHECKPOINT, config=config,
                        dagger=DaggerConfig(reference=reference), weights={SCENARIO: 1.0}, env_config={})


def _checkpoint(out, identity, version=3):
    """A checkpoint in ``out`` committed with ``identity`` before its first iteration (as ``save_partial`` writes
    one)."""
    folder = out / CHECKPOINT_DIR
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "progress.json").write_text(json.dumps({
        "schema": "dv2s-dagger-checkpoint", "version": version, "identity": identity, "iteration": 0,
        "history": [], "rng": {}, "envs": [], "partial": None}), encoding="utf-8")
    return folder


@pytest.fixture
def driver(tmp_path, monkeypatch):
    """A reference driver in the user's own module ``refdrv`` (on the Python path)."""
    folder = tmp_path / "drivers"
    folder.mkdir()
    (folder / "refdrv.py").write_text(DRIVER, encoding="utf-8")
    monkeypatch.syspath_prepend(str(folder))
    return folder / "refdrv.py"


def test_the_identity_records_the_code_and_the_reference_drivers_fingerprint(tmp_path, driver):
    identity = _identity(tmp_path / "run", "refdrv:Driver")
    assert identity[REFERENCE_FINGERPRINT]["module refdrv source (SHA-256)"] == file_sha256(driver)
    assert len(identity[CODE_IDENTITY]["dv2s sources (SHA-256)"]) == 64
    assert identity["reference"] == "refdrv:Driver"


def test_an_unchanged_reference_resumes_and_an_edited_one_is_refused_naming_it(tmp_path, driver):
    out = tmp_path / "run"
    folder = _checkpoint(out, _identity(out, "refdrv:Driver"))
    saved = DAggerCheckpoint(folder, _identity(out, "refdrv:Driver")).load()
    assert saved is not None and saved.iteration == 0
    before = file_sha256(driver)
    driver.write_text(DRIVER + "Driver.slower = True\n", encoding="utf-8")
    with pytest.raises(RunIdentityError) as error:
        DAggerCheckpoint(folder, _identity(out, "refdrv:Driver")).load()
    message = str(error.value)
    assert f"{out} holds a DAgger run whose reference driver refdrv:Driver has changed since" in message
    assert f"module refdrv source (SHA-256): run has {before[:12]}, now {file_sha256(driver)[:12]}" in message
    assert "restore the reference driver" in message


def test_a_replaced_registered_reference_is_refused(tmp_path):
    """The reference ``rule`` recorded as implemented by another module than the one registered now (a plug-in
    that replaced it): refused, naming both."""
    out = tmp_path / "run"
    recorded = _identity(out, "rule")
    fingerprint = recorded[REFERENCE_FINGERPRINT]
    (module_fact,) = [key for key in fingerprint if key.startswith("module ")]
    assert module_fact == "module policies.rule_based source (SHA-256)"
    replaced = {**recorded, REFERENCE_FINGERPRINT: {
        **{key: value for key, value in fingerprint.items() if key != module_fact},
        "module myplugins.drivers source (SHA-256)": "0" * 64}}
    folder = _checkpoint(out, replaced)
    with pytest.raises(RunIdentityError, match=r"whose reference driver rule has changed since \(module "
                                               r"myplugins\.drivers source \(SHA-256\): run has 000000000000, now "
                                               r"absent; module policies\.rule_based source \(SHA-256\): run has "
                                               r"absent, now [0-9a-f]{12}\)"):
        DAggerCheckpoint(folder, _identity(out, "rule")).load()
    assert DAggerCheckpoint(_checkpoint(tmp_path / "same", recorded), _identity(out, "rule")).load() is not None


def test_a_checkpoint_made_with_other_code_is_refused(tmp_path):
    out = tmp_path / "run"
    recorded = _identity(out, "rule")
    other = {**recorded, CODE_IDENTITY: {**recorded[CODE_IDENTITY], "dv2s sources (SHA-256)": "1" * 64}}
    with pytest.raises(RunIdentityError, match=r"holds an unfinished DAgger run made with other code \(dv2s sources "
                                               r"differ: dv2s sources \(SHA-256\): run has 111111111111"):
        DAggerCheckpoint(_checkpoint(out, other), _identity(out, "rule")).load()


def test_a_checkpoint_of_the_earlier_format_is_refused_with_the_fix(tmp_path):
    out = tmp_path / "run"
    recorded = {key: value for key, value in _identity(out, "rule").items()
                if key not in (CODE_IDENTITY, REFERENCE_FINGERPRINT)}
    folder = _checkpoint(out, recorded, version=2)
    with pytest.raises(DAggerResumeError, match=r"written by another version of dv2s-gym \(its progress\.json records "
                                                r"format 2, this dv2s-gym reads format 3\); start a new --out folder"):
        DAggerCheckpoint(folder, _identity(out, "rule")).load()
