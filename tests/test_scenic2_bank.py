"""Bank.add from Python upgrades Scenic 2 on request (rewrites in provenance) and otherwise names the construct."""

import json

import pytest

from scenario_bank.bank import Bank, ScenarioRejectedError, Sidecar
from test_scenic2_upgrade import HIGHWAY_SCENIC2


@pytest.mark.slow
def test_bank_add_upgrades_scenic2_on_request_and_records_the_rewrites(tmp_path):
    bank = Bank(tmp_path / "bank")
    entry = bank.add(HIGHWAY_SCENIC2, Sidecar(description="A car ahead on a highway.", name="old"),
                     upgrade_scenic2=True)
    assert "ego = new Car at" in entry.script and "\nnew Car following" in entry.script
    rewrites = entry.source.scenic2_rewrites
    assert len(rewrites) == 2 and rewrites[0].startswith("line 4: ego = Car at") and "new Car" in rewrites[1]
    assert any("requireVisible" in n for n in entry.source.scenic2_notes)
    reloaded = Bank(tmp_path / "bank").get("old")  # persisted in the sidecar
    assert reloaded.source.scenic2_rewrites == rewrites and reloaded.script == entry.script
    sidecar = json.loads((entry.folder / "meta.json").read_text())
    assert sidecar["source"]["scenic2_rewrites"] == list(rewrites)


def test_bank_add_without_the_option_names_the_scenic2_construct_and_the_fix(tmp_path):
    bank = Bank(tmp_path / "bank")
    with pytest.raises(ScenarioRejectedError) as caught:
        bank.add(HIGHWAY_SCENIC2, Sidecar(description="A car ahead on a highway.", name="old"))
    message = str(caught.value)
    assert "is Scenic 2: line 4: `ego = Car at lane.centerline" in message
    assert "'new Car'" in message and "upgrade_scenic2=True" in message
    assert "\n" not in message
    assert Bank(tmp_path / "bank").names() == []


@pytest.mark.slow
def test_scenic3_script_with_the_option_is_stored_unchanged_without_scenic2_provenance(tmp_path):
    from scenario_bank.scenic2 import upgrade_scenic2

    scenic3 = upgrade_scenic2(HIGHWAY_SCENIC2).source
    entry = Bank(tmp_path / "bank").add(scenic3, Sidecar(description="A car ahead on a highway.", name="new3",
                                                         source={"kind": "hand-written"}), upgrade_scenic2=True)
    assert entry.script == scenic3 and entry.source.scenic2_rewrites is None
    assert "scenic2_rewrites" not in json.loads((entry.folder / "meta.json").read_text())["source"]


def test_add_with_merge_upgrades_too(tmp_path):
    outcome = Bank(tmp_path / "bank").add(HIGHWAY_SCENIC2, Sidecar(description="A car ahead on a highway.", name="old"),
                                          upgrade_scenic2=True, on_duplicate="merge")
    assert outcome.entry.source.scenic2_rewrites and "new Car" in outcome.entry.script


@pytest.mark.slow
def test_env_names_a_scenic2_duration_as_the_construct(tmp_path):
    """A Scenic 2 script whose only Scenic 2 syntax is a duration without a unit: the env says so."""
    import gymnasium as gym

    from envs.errors import ScenarioCompileError
    from scenario_bank.scenic2 import upgrade_scenic2

    scenic3 = upgrade_scenic2(HIGHWAY_SCENIC2).source
    script = tmp_path / "old.scenic"
    script.write_text(scenic3 + "terminate after 5\n")
    with pytest.raises(ScenarioCompileError) as caught:
        gym.make("dv2s_gym:DV2S-v0", scenario=str(script), config={"duration": 1.0})
    message = str(caught.value)
    assert "Scenic 2 syntax: `terminate after 5` (line 8)" in message and "needs the unit" in message
    assert "upgrade_scenic2: True" in message
    env = gym.make("dv2s_gym:DV2S-v0", scenario=str(script), config={"duration": 1.0, "upgrade_scenic2": True})
    env.reset(seed=0)
    env.step(1)
    env.close()
