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


@pytest.fixture(autouse=True)
def _scenic_globals_idle():
    """Start every test with Scenic's global state idle, whatever the tests before it left running.

    An env stepping a simulation in this process keeps it in Scenic's module globals between steps
    (``envs.scenic_highway.stepping``); the package's own compiles set it aside first, but a test
    compiling with Scenic directly would trip over it ("assert currentSimulation is None") and leave
    Scenic half-activated for every later test in the worker: which test ran before depends on how
    xdist shares the tests out. Setting it aside is what ``compile_scenario`` does; a suspended
    simulation takes its globals back at its next step.
    """
    stepping = sys.modules.get("envs.scenic_highway.stepping")
    if stepping is not None:
        stepping.release_veneer()
    yield


@pytest.fixture(scope="module")
def in_process_simulator():
    """Run the test's own Scenic scripts in this process: for tests of the simulator's internals.

    Product code runs every script the package does not ship in the jail (tests/test_jail.py
    checks that a jailed episode equals the in-process one); these tests read the road,
    vehicles and compiled scenarios directly, which only exist in the process that simulates.
    """
    import envs.dv2s_env as dv2s_env
    import envs.scenarios as scenarios

    original = scenarios.compile_scenario

    def compile_trusted(*args, **kwargs):
        kwargs["trusted"] = True
        return original(*args, **kwargs)

    # module scope, so that the module's own module-scoped fixtures (a compiled highway, a
    # simulated run) are built in this process too
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(dv2s_env, "_all_shipped", lambda texts, config: True)
        patch.setattr(dv2s_env, "_is_shipped", lambda text: True)
        patch.setattr(scenarios, "compile_scenario", compile_trusted)
        yield


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
