"""A plug-in failure type (tests/plugin_hard_brake.py, a module registering its row and detector when imported) is
detected in the worker processes of ``dv2s mine`` and ``dv2s regress`` alike with one and two workers: every
worker imports the plug-in modules the registries remember. A plug-in registered in ``__main__`` is refused with
the fix; a plug-in module a worker cannot import stops the run naming it; ``DV2S_PLUGINS`` names plug-ins to the
command."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dv2s_gym.mining import monitors
from dv2s_gym.regress.errors import RegressError
from scenario_bank.failure_types import FAILURE_TABLE, FailureType, failure_type, register_failure_type
from scenario_bank.failure_types import unregister_failure_type
from scenario_bank.plugins import PLUGINS_VARIABLE, code_modules, forget_plugin, plugin_modules, remember_plugin
from tests.cli_helpers import one_line_error, run
from tests.regress_call import run_regression

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = "tests.plugin_hard_brake"
QUICK = ["--config", '{"duration": 5}', "--no-progress", "--no-convert"]
SCENARIOS = ["highway_lead_vehicle_brakes", "highway_cut_in_from_left"]


@pytest.fixture
def plugin():
    """The plug-in module, imported (so registered) in this process only; undone after."""
    module = importlib.import_module(PLUGIN)
    yield module
    module.unregister()


def _mined(out: Path):
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines() if line.strip()]
    return sorted((r["index"], r["scenario"], r["seed"], r["result"]["trajectory_hash"], r["error"],
                   (r["failure"] or {}).get("type"), (r["failure"] or {}).get("step")) for r in rows)


@pytest.mark.slow
def test_mining_detects_a_plugin_type_alike_with_one_and_two_workers(plugin, tmp_path, capsys):
    assert plugin_modules() == [PLUGIN]  # the module that registered the row and the detector
    runs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}"
        code, _, err = run(capsys, "mine", "--policy", "idm", "--scenarios", *SCENARIOS, "--budget", "6",
                           "--workers", workers, "--out", out, *QUICK)
        assert code == 0, err
        runs.append(_mined(out))
    assert runs[0] == runs[1]
    types = [row[5] for row in runs[0]]
    assert not any(row[4] for row in runs[0])  # no episode ended in an error
    assert plugin.NAME in types and None in types  # detected in some episodes, not in others


@pytest.mark.slow
def test_regress_records_a_plugin_type_alike_with_one_and_two_workers(plugin, tmp_path):
    reports = [run_regression("idm", scenarios=SCENARIOS, episodes=3, workers=workers, out_dir=tmp_path / f"w{workers}",
                              env_config={"duration": 5}, failure=["collision", plugin.NAME], progress=False,
                              clips=False) for workers in (1, 2)]
    episodes = [[(e["id"], e["candidate"]["error"], e["candidate"]["hard_braked"], e["candidate"]["failure_kinds"])
                 for e in report.to_dict()["episodes"]] for report in reports]
    assert episodes[0] == episodes[1]
    assert not any(error for _, error, _, _ in episodes[0])
    assert {braked for _, _, braked, _ in episodes[0]} == {True, False}
    assert reports[0].to_dict()["scenarios"][SCENARIOS[0]]["candidate"]["hard_brake_rate"]["count"] >= 1


@pytest.fixture
def in_main():
    """A failure type and detector registered as a script's own code would (in ``__main__``); undone after."""
    register_failure_type(FailureType("in_main", severity=len(FAILURE_TABLE), result_field="in_main_seen",
                                      regress_default=False, with_actor=False, label=None), module="__main__")

    def detect(result, trace, settings):
        return None

    detect.__module__ = "__main__"
    monitors.register_detector(monitors.Detector("in_main", detect, lambda result, failure, settings: -1.0))
    yield
    monitors.unregister_detector("in_main")
    unregister_failure_type("in_main")


@pytest.mark.slow
def test_a_plugin_registered_in_main_is_refused_with_the_fix(in_main, tmp_path, capsys):
    code, _, err = run(capsys, "mine", "--policy", "idm", "--scenarios", SCENARIOS[0], "--budget", "1",
                       "--workers", "1", "--out", tmp_path / "run", *QUICK)
    line = one_line_error(err)
    assert code == 2 and "failure type 'in_main'" in line and "__main__" in line
    assert "importable module" in line and PLUGINS_VARIABLE in line
    with pytest.raises(RegressError, match="registered in __main__.*importable module"):
        run_regression("idm", scenarios=SCENARIOS[:1], episodes=1, workers=2, out_dir=tmp_path / "regress",
                       progress=False, clips=False)


@pytest.mark.slow
def test_a_script_registering_at_its_top_is_refused_too(tmp_path):
    """The way a user meets it: a script that registers a type, then runs ``dv2s mine`` through ``main()``."""
    script = tmp_path / "my_miner.py"
    script.write_text(textwrap.dedent(f"""\
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        from dv2s_gym.cli import main
        from dv2s_gym.mining.monitors import Detector, register_detector
        from scenario_bank.failure_types import FailureType, register_failure_type

        register_failure_type(FailureType("swerve", severity=9, result_field=None, regress_default=False,
                                          with_actor=False, label=None))
        register_detector(Detector("swerve", lambda result, trace, settings: None, lambda *args: -1.0))
        if __name__ == "__main__":
            sys.exit(main(sys.argv[1:]))
        """))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, str(script), "mine", "--policy", "idm", "--scenarios", SCENARIOS[0],
                           "--budget", "1", "--workers", "2", "--out", str(tmp_path / "run"), *QUICK],
                          capture_output=True, text=True, env=env, timeout=300)
    line = one_line_error(done.stderr)
    assert done.returncode == 2 and "failure type 'swerve'" in line and "__main__" in line
    assert "importable module" in line and not (tmp_path / "run" / "episodes.jsonl").exists()


@pytest.fixture
def missing_plugin():
    """A plug-in module remembered here that no worker can import."""
    remember_plugin("failure type 'ghost'", "no_such_plugin_module")
    yield "no_such_plugin_module"
    forget_plugin("failure type 'ghost'")


@pytest.mark.slow
def test_a_worker_that_cannot_import_a_plugin_stops_the_run_naming_it(missing_plugin, tmp_path):
    with pytest.raises(RegressError, match=f"plug-in module '{missing_plugin}' cannot be imported in a worker "
                                           "process \\(ModuleNotFoundError"):
        run_regression("idm", scenarios=SCENARIOS[:1], episodes=1, workers=1, out_dir=tmp_path / "regress",
                       progress=False, clips=False)


def test_a_ray_actor_that_cannot_import_a_plugin_says_which():
    pytest.importorskip("ray")
    from dv2s_gym.workers.ray_pool import EpisodeActor

    assert EpisodeActor([PLUGIN]).start_problem() is None
    problem = EpisodeActor(["no_such_plugin_module"]).start_problem()
    assert "plug-in module 'no_such_plugin_module' cannot be imported in a worker process" in problem
    importlib.import_module(PLUGIN).unregister()  # the actor's import registered it in this process


def test_the_environment_variable_names_plugins_to_the_command(monkeypatch, capsys):
    monkeypatch.setenv(PLUGINS_VARIABLE, f" {PLUGIN} ,")
    try:
        code, _, _ = run(capsys, "bank", "list")
        assert code == 0 and failure_type("hard_brake") is not None
        assert PLUGIN in plugin_modules()
    finally:
        importlib.import_module(PLUGIN).unregister()
        forget_plugin(f"{PLUGINS_VARIABLE}={PLUGIN}")
    monkeypatch.setenv(PLUGINS_VARIABLE, "no_such_plugin_module")
    code, _, err = run(capsys, "bank", "list")
    line = one_line_error(err)
    assert code == 2 and "plug-in module 'no_such_plugin_module' cannot be imported" in line
    assert PLUGINS_VARIABLE in line


def test_a_plugin_whose_own_code_raises_is_told_from_one_not_found(monkeypatch, capsys, tmp_path):
    (tmp_path / "boom_plugin.py").write_text('raise RuntimeError("boom")\n')
    (tmp_path / "needs_a_dependency.py").write_text("import no_such_dependency_module\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv(PLUGINS_VARIABLE, "boom_plugin")
    code, _, err = run(capsys, "bank", "list")
    line = one_line_error(err)
    assert code == 2 and "importing it raised RuntimeError: boom" in line
    assert "run `python -c 'import boom_plugin'` to see the traceback" in line and "Python path" not in line
    monkeypatch.setenv(PLUGINS_VARIABLE, "needs_a_dependency")
    code, _, err = run(capsys, "bank", "list")
    line = one_line_error(err)
    assert code == 2 and "No module named 'no_such_dependency_module'" in line and "Python path" not in line
    assert "import needs_a_dependency" in line
    monkeypatch.setenv(PLUGINS_VARIABLE, "no_such_plugin_module")
    _, _, err = run(capsys, "bank", "list")
    assert "Python path of every worker" in one_line_error(err)


@pytest.fixture
def registries(monkeypatch):
    """The policy, sampler and DRA/SG registries as copies, dropped after the test."""
    from dv2s_gym.mining.sampling import samplers
    from dv2s_gym.pipeline import stages
    from policies import registry

    monkeypatch.setattr(registry, "_REGISTRY", registry._REGISTRY.copy())
    monkeypatch.setattr(samplers, "_REGISTRY", samplers._REGISTRY.copy())
    monkeypatch.setattr(stages, "_DRA_REGISTRY", stages._DRA_REGISTRY.copy())
    monkeypatch.setattr(stages, "_SG_REGISTRY", stages._SG_REGISTRY.copy())
    yield registry, samplers, stages
    sys.modules.pop("my_registrations", None)


def test_a_policy_registration_remembers_the_module_that_made_it(registries, monkeypatch, tmp_path):
    """Policies run in the worker processes, so their registering module is remembered; samplers and DRA/SG
    backends run in the parent process only, so a registration of theirs (even in ``__main__``) is no plug-in."""
    registry, samplers, stages = registries
    (tmp_path / "my_registrations.py").write_text(textwrap.dedent("""\
        from dv2s_gym.mining.sampling.samplers import SamplerRecord, register_sampler
        from dv2s_gym.pipeline.stages import register_dra, register_sg
        from policies.registry import register_policy
        register_policy("my_idle", lambda **options: (lambda obs: 1))
        register_sampler("my_sampler", SamplerRecord(lambda space, features, params: None))
        register_dra("my_dra", lambda clip, **options: ("", {}))
        register_sg("my_sg", lambda description, **options: None)
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.import_module("my_registrations")
    assert plugin_modules() == ["my_registrations"]
    forget_plugin("policy 'my_idle'")
    assert plugin_modules() == []  # the product's own registrations and the parent-only ones are no plug-ins
    assert code_modules() == ["my_registrations"]  # but the code of its sampler and backends is the run's
    registry.register_policy("in_main", lambda **options: (lambda obs: 1))  # this test module's, as a script's
    assert plugin_modules() == [__name__]


def test_a_policy_registered_in_main_is_refused_with_the_fix(registries):
    from scenario_bank.plugins import PluginError, check_plugins

    registry, _, _ = registries
    exec(compile("register_policy('from_main', lambda **options: (lambda obs: 1))", "<script>", "exec"),
         {"__name__": "__main__", "register_policy": registry.register_policy})
    with pytest.raises(PluginError, match="policy 'from_main' is registered in __main__.*importable module"):
        check_plugins()


@pytest.mark.slow
def test_a_policy_registered_by_an_imported_module_reaches_the_workers(registries, tmp_path):
    plugin_policy = importlib.import_module("tests.plugin_idle_policy")
    try:
        assert plugin_modules() == ["tests.plugin_idle_policy"]  # imported here only, not named by DV2S_PLUGINS
        report = run_regression(plugin_policy.NAME, scenarios=SCENARIOS[:1], episodes=2, workers=2,
                                out_dir=tmp_path / "regress", env_config={"duration": 6}, progress=False,
                                clips=False)
        assert [e["candidate"]["error"] for e in report.to_dict()["episodes"]] == [None, None]
    finally:
        sys.modules.pop("tests.plugin_idle_policy", None)
