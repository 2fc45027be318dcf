"""The seam between the bank's script checks and the simulator layer that runs them."""

from __future__ import annotations

import pytest

import scenario_bank.simulator_worker as seam
from scenario_bank.errors import DV2SError
from scenario_bank.sandbox import check_in_jail, run_in_sandbox, verify_script

SCRIPT = "param speed = 30\n"


def test_importing_envs_names_its_jail_worker():
    import envs  # noqa: F401

    assert seam.simulator_worker() == "envs.jail_worker"


@pytest.mark.parametrize("check", [
    lambda: run_in_sandbox(SCRIPT, name="probe"),
    lambda: verify_script(SCRIPT, name="probe", use_cache=False),
    lambda: check_in_jail(SCRIPT, name="probe"),
])
def test_a_check_without_a_simulator_says_what_to_import(monkeypatch, check):
    monkeypatch.setattr(seam, "_WORKER", None)
    with pytest.raises(seam.NoSimulatorError, match=r"no simulator is loaded: `import envs`") as raised:
        check()
    assert isinstance(raised.value, DV2SError)


@pytest.mark.parametrize("bad", ["", "envs/jail_worker", "envs..jail_worker", None])
def test_the_worker_is_a_dotted_module_name(monkeypatch, bad):
    monkeypatch.setattr(seam, "_WORKER", "envs.jail_worker")
    with pytest.raises(ValueError, match="dotted module name"):
        seam.use_simulator_worker(bad)
    assert seam.simulator_worker() == "envs.jail_worker"
