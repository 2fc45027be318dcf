"""A plug-in module whose own code raises when a worker process imports it: the advice says to import it as a
worker process does (it may import in the process that started the workers)."""

from __future__ import annotations

import sys

import pytest

from scenario_bank.plugins import PluginError, import_plugins

__all__: list = []


def test_the_advice_for_a_worker_names_the_worker_process(tmp_path, monkeypatch):
    (tmp_path / "raises_in_workers.py").write_text('raise RuntimeError("only in workers")\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(PluginError) as refused:
        import_plugins(["raises_in_workers"], where="a worker process")
    message = str(refused.value)
    assert "cannot be imported in a worker process: importing it raised RuntimeError: only in workers" in message
    assert "run `python -c 'import raises_in_workers'` as a worker process does" in message
    with pytest.raises(PluginError) as here:
        import_plugins(["raises_in_workers"])
    assert "run `python -c 'import raises_in_workers'` to see the traceback" in str(here.value)
    sys.modules.pop("raises_in_workers", None)
