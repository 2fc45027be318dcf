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


@pytest.mark.slow
def test_a_tag_selection_resumes_over_the_scenarios_it_chose_though_the_bank_grew(tmp_path):
    """A run over ``tag:...`` mines the scenarios the tag chose when it began: an entry the bank gained since with
    that tag (a mined bank grows under its own runs) does not make the same command a run with other settings."""
    import shutil

    from scenario_bank.bank import BANK_DIR

    bank = tmp_path / "bank"
    bank.mkdir()
    shutil.copytree(BANK_DIR / "highway_lead_vehicle_stopped", bank / "highway_lead_vehicle_stopped")
    settings = MineSettings(budget=1, scenarios=("tag:lead_vehicle_stopped",), bank_dir=str(bank), convert=False)
    mine("rule", settings, out=tmp_path / "run", progress=False, reports=False)
    shutil.copytree(BANK_DIR / "urban_lead_vehicle_stopped", bank / "urban_lead_vehicle_stopped")
    run = mine("rule", settings.replace(budget=2), out=tmp_path / "run", progress=False, reports=False)
    assert [r.scenario for r in run.records] == ["highway_lead_vehicle_stopped"] * 2
    with pytest.raises(RunIdentityError, match=r"scenarios: the run has 1, asked adds \['urban_lead_vehicle_stopped'\]"):
        mine("rule", settings.replace(budget=3, scenarios=("tag:lead_vehicle_stopped", "urban_lead_vehicle_stopped")),
             out=tmp_path / "run", progress=False, reports=False)


@pytest.mark.slow
def test_a_selection_is_recorded_once_and_resumes_by_its_terms_in_any_order(tmp_path):
    """The run's selection is the one it began with: a resume spelling it otherwise (a name its tag already chose)
    does not rewrite it, so the run's own command resumes after the bank grew, as does the same terms reordered or
    repeated; a spelling that now chooses another scenario is refused."""
    import json
    import shutil

    from scenario_bank.bank import BANK_DIR

    bank = tmp_path / "bank"
    bank.mkdir()
    for name in ("highway_lead_vehicle_stopped", "highway_lead_vehicle_brakes"):
        shutil.copytree(BANK_DIR / name, bank / name)
    selection = ("tag:lead_vehicle_stopped", "highway_lead_vehicle_brakes")
    respelt = ("tag:lead_vehicle_stopped", "highway_lead_vehicle_stopped", "highway_lead_vehicle_brakes")
    settings = MineSettings(budget=1, scenarios=selection, bank_dir=str(bank), convert=False)
    out = tmp_path / "run"

    def recorded_selection():
        return json.loads((out / "settings.json").read_text())["selection"]

    mine("rule", settings, out=out, progress=False, reports=False)
    mine("rule", settings.replace(budget=2, scenarios=respelt), out=out, progress=False, reports=False)
    assert recorded_selection() == list(selection)
    shutil.copytree(BANK_DIR / "urban_lead_vehicle_stopped", bank / "urban_lead_vehicle_stopped")
    mine("rule", settings.replace(budget=3), out=out, progress=False, reports=False)
    reordered = ("highway_lead_vehicle_brakes", "tag:lead_vehicle_stopped", "highway_lead_vehicle_brakes")
    run = mine("rule", settings.replace(budget=4, scenarios=reordered), out=out, progress=False, reports=False)
    assert {r.scenario for r in run.records} <= {"highway_lead_vehicle_stopped", "highway_lead_vehicle_brakes"}
    assert len(run.records) == 4 and recorded_selection() == list(selection)
    assert json.loads((out / "settings.json").read_text())["scenarios"] == ["highway_lead_vehicle_stopped",
                                                                            "highway_lead_vehicle_brakes"]
    with pytest.raises(RunIdentityError, match=r"scenarios: the run has 2, asked adds \['urban_lead_vehicle_stopped'\]"):
        mine("rule", settings.replace(budget=5, scenarios=respelt), out=out, progress=False, reports=False)


@pytest.mark.slow
def test_a_resume_over_a_scenario_the_bank_no_longer_holds_says_so(tmp_path):
    """The recorded scenarios come from the run, not the command line: the refusal names the run and the bank."""
    import shutil

    from dv2s_gym.mining.errors import MiningError
    from scenario_bank.bank import BANK_DIR

    bank = tmp_path / "bank"
    for name in ("highway_lead_vehicle_stopped", "urban_lead_vehicle_stopped"):
        shutil.copytree(BANK_DIR / name, bank / name)
    settings = MineSettings(budget=1, scenarios=("tag:lead_vehicle_stopped",), bank_dir=str(bank), convert=False)
    mine("rule", settings, out=tmp_path / "run", progress=False, reports=False)
    shutil.rmtree(bank / "urban_lead_vehicle_stopped")
    with pytest.raises(MiningError, match=r"holds a mining run over 'urban_lead_vehicle_stopped', which the bank at "
                                          r".* no longer holds; restore it"):
        mine("rule", settings.replace(budget=2, scenarios=None), out=tmp_path / "run", progress=False, reports=False)
