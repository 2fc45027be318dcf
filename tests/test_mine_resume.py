"""Resuming a mining run with other settings is refused before the scene space is built."""

from __future__ import annotations

import pytest

from mining_helpers import SpaceBuilt, recorded_run_folder
from dv2s_gym.mining.miner import mine
from dv2s_gym.mining.settings import MineSettings
from scenario_bank.run_identity import RunIdentityError

SCENARIOS = ("highway_lead_vehicle_brakes",)



@pytest.fixture
def run_folder(tmp_path, monkeypatch):
    """A run folder whose settings.json a seed-0 run wrote; building a scene space raises :class:`SpaceBuilt`."""
    return recorded_run_folder(tmp_path / "run", SCENARIOS, monkeypatch)


def test_a_changed_seed_is_refused_before_the_space_is_built(run_folder):
    with pytest.raises(RunIdentityError, match=r"holds a mining run with other settings \(seed: run has 0, asked 1\)"):
        mine("rule", MineSettings(budget=2, scenarios=SCENARIOS, seed=1), out=run_folder, progress=False,
             reports=False)


def test_the_same_settings_go_on_to_build_the_space(run_folder):
    with pytest.raises(SpaceBuilt):  # the early check passes what the full one would
        mine("rule", MineSettings(budget=2, scenarios=SCENARIOS, seed=0), out=run_folder, progress=False,
             reports=False)
