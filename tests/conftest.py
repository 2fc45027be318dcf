"""Shared pytest setup: make the repository importable without installing it, and keep
the tests' caches (bank indexes, parsed maps) in a throwaway directory instead of the
user's cache directory. Subprocesses inherit both."""

import os

import pytest
import sys
import tempfile
from pathlib import Path

# two xdist workers on two cores: one BLAS/OpenMP thread each, or they slow each other down
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("DV2S_CACHE_DIR", tempfile.mkdtemp(prefix="dv2s-test-cache-"))

# DV2S_TEST_CPU_LOG=path records each test's CPU time (tests/cpu_time_plugin.py)
pytest_plugins = ["cpu_time_plugin"]

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from scenic_fixtures import in_process_simulator, scenic_globals_idle  # noqa: E402,F401  (shared with bench/tests)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """Run the modules that hold slow tests first, each module's tests still together and in order.

    Under ``-n 2`` a module of minutes-long tests collected last keeps one worker busy while the other has
    nothing left; started first, the short tests fill in around it. Only the order changes (a stable sort,
    modules kept whole so their module-scoped fixtures are built once); the quick run (``-m "not slow"``)
    has no slow test and keeps the collection order.
    """
    slow_tests = {}
    for item in items:
        if item.get_closest_marker("slow") is not None:
            slow_tests[item.path] = slow_tests.get(item.path, 0) + 1
    if slow_tests:
        items.sort(key=lambda item: -slow_tests.get(item.path, 0))


@pytest.fixture(autouse=True)
def plugin_modules_per_test(monkeypatch):
    """A test's registrations (a policy, a sampler, a backend registered by a test module or a module in a
    temporary folder) are remembered as plug-in modules for that test only: a later test's worker processes
    would otherwise import them too (and a later run's code identity name them), and a module in a removed folder
    cannot be imported."""
    import scenario_bank.plugins as plugins

    monkeypatch.setattr(plugins, "_ORIGINS", dict(plugins._ORIGINS))
    monkeypatch.setattr(plugins, "_PARENT_ORIGINS", dict(plugins._PARENT_ORIGINS))
