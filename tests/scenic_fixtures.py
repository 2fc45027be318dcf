"""Fixtures shared by the product's tests (tests/conftest.py) and the benchmarks' tests (bench/tests/conftest.py):
Scenic's global state idle before every test, and Scenic scripts run in the test's own process."""

import sys

import pytest


@pytest.fixture(autouse=True)
def scenic_globals_idle():
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
