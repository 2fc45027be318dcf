"""The jail refuses to start, with the right fix, where it would hide the code it must run."""

from __future__ import annotations

from pathlib import Path

import pytest

from scenario_bank.jail import bwrap, process
from scenario_bank.jail.errors import JailUnavailableError


@pytest.mark.parametrize("where", ["/tmp/clone", "/dev/shm/clone"])
def test_code_under_the_jail_s_own_scratch_is_named_with_its_fix(monkeypatch, where):
    monkeypatch.setattr(bwrap, "CODE_ROOT", Path(where))
    monkeypatch.setattr(bwrap, "bwrap_path", lambda: "/usr/bin/bwrap")
    monkeypatch.setattr(process, "_STATUS", {})
    assert bwrap.hidden_by_scratch() == where
    with pytest.raises(JailUnavailableError) as caught:
        process.require_jail("this script")
    message = str(caught.value)
    assert f"{where} is under" in message and "outside" in message and "/var/tmp" in message
    assert "install bubblewrap" not in message


def test_code_elsewhere_is_not_hidden(monkeypatch):
    monkeypatch.setattr(bwrap, "CODE_ROOT", Path("/var/tmp/tmpclone"))
    monkeypatch.setattr(bwrap, "_python_roots", lambda: ["/opt/venv", "/tmpfoo/venv"])
    assert bwrap.hidden_by_scratch() is None


def test_mining_that_converts_refuses_to_start_where_the_jail_hides_the_code(monkeypatch, tmp_path):
    """Every conversion runs scripts in the jail: without it the run would reject each failure for the same reason,
    so it stops before any episode with that reason and its fix."""
    pytest.importorskip("verifai")
    from dv2s_gym.mining.errors import MiningError
    from dv2s_gym.mining.miner import mine
    from dv2s_gym.mining.settings import MineSettings

    monkeypatch.setattr(bwrap, "CODE_ROOT", Path("/tmp/clone"))
    monkeypatch.setattr(process, "_STATUS", {})
    settings = MineSettings(budget=1, scenarios=("highway_lead_vehicle_brakes",), convert=True,
                            bank_dir=str(tmp_path / "bank"))
    with pytest.raises(MiningError) as refused:
        mine("rule", settings, out=tmp_path / "run", progress=False)
    message = str(refused.value)
    assert "/tmp/clone is under /tmp" in message and "outside /tmp" in message and "--no-convert" in message
    assert not (tmp_path / "run").exists() and not (tmp_path / "bank").exists()
