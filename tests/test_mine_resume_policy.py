"""Resuming a mining run whose policy changed under the same spec is refused, naming what changed and the fix."""

from __future__ import annotations

import json
import shutil
import zipfile

import pytest

import dv2s_gym.mining.sampling.space as space_module
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.miner import _recorded, mine
from dv2s_gym.mining.settings import MineSettings
from policies.run_identity import RESUME_FINGERPRINT
from policies.registry import SHIPPED_CHECKPOINT

SCENARIOS = ("highway_lead_vehicle_brakes",)


class _SpaceBuilt(Exception):
    pass


def _run_folder(tmp_path, policy):
    out = tmp_path / "run"
    (out / "traces").mkdir(parents=True)
    recorded = _recorded(policy, MineSettings(budget=2, scenarios=SCENARIOS, batch=4), SCENARIOS, {})
    (out / "settings.json").write_text(json.dumps(recorded), encoding="utf-8")
    return out


@pytest.fixture
def no_space(monkeypatch):
    def refuse(*args, **kwargs):
        raise _SpaceBuilt()
    monkeypatch.setattr(space_module, "SceneSpace", refuse)


def _mine(policy, out):
    mine(policy, MineSettings(budget=2, scenarios=SCENARIOS), out=out, progress=False, reports=False)


def test_a_changed_policy_module_is_refused(tmp_path, monkeypatch, no_space):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "respol.py").write_text("def drive(obs, info=None):\n    return 3\n")
    out = _run_folder(tmp_path, "respol:drive")
    with pytest.raises(_SpaceBuilt):  # unchanged: resumes
        _mine("respol:drive", out)
    (tmp_path / "respol.py").write_text("def drive(obs, info=None):\n    return 4\n")
    with pytest.raises(MiningError) as error:
        _mine("respol:drive", out)
    message = str(error.value)
    assert "\n" not in message and "whose policy has changed since" in message
    assert "module respol source (SHA-256): run has" in message
    assert "restore the policy" in message and "new --out" in message


def test_a_checkpoint_replaced_in_place_is_refused(tmp_path, no_space):
    checkpoint = tmp_path / "model.zip"
    shutil.copyfile(SHIPPED_CHECKPOINT, checkpoint)
    spec = f"ppo:{checkpoint}"
    out = _run_folder(tmp_path, spec)
    with zipfile.ZipFile(checkpoint, "a") as archive:  # other bytes, still a loadable checkpoint
        archive.writestr("note.txt", "replaced in place")
    with pytest.raises(MiningError, match=r"whose policy has changed since \(checkpoint .*model\.zip \(SHA-256\): "
                                          r"run has [0-9a-f]{12}, now [0-9a-f]{12}\)"):
        _mine(spec, out)


def test_a_run_folder_whose_record_lacks_the_policy_fingerprint_is_refused_naming_the_facts(tmp_path, no_space):
    out = _run_folder(tmp_path, "rule")
    recorded = json.loads((out / "settings.json").read_text(encoding="utf-8"))
    del recorded[RESUME_FINGERPRINT]
    (out / "settings.json").write_text(json.dumps(recorded), encoding="utf-8")
    with pytest.raises(MiningError) as error:
        _mine("rule", out)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{out} holds a mining run of rule whose policy has changed ")
    assert "dv2s version: run has absent, now " in message and message.endswith("or pass a new --out")
