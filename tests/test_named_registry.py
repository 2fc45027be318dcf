"""The one registry type behind every plug-in table, and the register functions built on it."""

from __future__ import annotations

import inspect

import pytest

from dv2s_gym.mining import monitors

from dv2s_gym.mining.sampling import samplers
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.pipeline import stages
from dv2s_gym.pipeline.errors import PipelineError
from dv2s_gym.workers import backends, tasks
from dv2s_gym.workers.errors import WorkerError
from policies import registry as policies
from policies.registry import PolicyError
from scenario_bank import failure_types
from scenario_bank.errors import BuiltInReplacedWarning, DV2SError
from scenario_bank.failure_types import FailureType, FailureTypeError
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import plugin_modules


class PlantedError(DV2SError, ValueError):
    """The project error of a registry made by these tests."""


def _registry() -> Registry[int]:
    return Registry("widget", PlantedError, {"one": 1, "two": 2})


def test_a_clash_names_the_name_and_the_fix_and_keeps_the_entry():
    table = _registry()
    with pytest.raises(PlantedError, match=r"^a widget named 'one' is already registered; pass overwrite=True to "
                                           r"replace it$"):
        table.register("one", 10)
    assert table.get("one") == 1
    for bad in ("", None, 3):
        with pytest.raises(PlantedError, match=f"^widget name {bad!r} must be a non-empty string$"):
            table.register(bad, 0)  # type: ignore[arg-type]
    assert table.names() == ["one", "two"]


def test_overwrite_replaces_in_place_with_its_module():
    table = _registry()
    assert table.register("one", 10, overwrite=True, module="my_plugins") == 10
    assert table.get("one") == 10 and table.names() == ["one", "two"] and table.module("one") == "my_plugins"
    table.register("one", 11, overwrite=True)  # a replacement without a module forgets the old one's
    assert table.get("one") == 11 and table.module("one") is None
    table.register("three", 3, module="other")
    assert table.names() == ["one", "two", "three"] and table.module("three") == "other"


def test_an_unknown_name_lists_the_known_ones_unless_a_default_is_given():
    table = _registry()
    with pytest.raises(PlantedError, match=r"^unknown widget 'tree': use one of one, two$"):
        table.get("tree")
    assert table.get("tree", None) is None and table.get("tree", 0) == 0
    empty: Registry[int] = Registry("widget", PlantedError)
    with pytest.raises(PlantedError, match="none is registered"):
        empty.get("one")
    worded = Registry("widget", PlantedError, {"one": 1},
                      unknown=lambda name, names: KeyError(f"{name} is not among {names}"))
    with pytest.raises(KeyError, match=r"tree is not among \['one'\]"):
        worded.get("tree")


def test_unregister_removes_the_entry_and_its_module_and_refuses_an_unknown_name():
    table = _registry()
    table.register("three", 3, module="my_plugins")
    assert table.unregister("three") == 3
    assert "three" not in table and table.module("three") is None and table.names() == ["one", "two"]
    with pytest.raises(PlantedError, match=r"^unknown widget 'three': use one of one, two$"):
        table.unregister("three")


def test_it_reads_and_writes_as_a_mapping_and_copies_apart():
    table = _registry()
    assert dict(table) == {"one": 1, "two": 2} and len(table) == 2 and sorted(table) == ["one", "two"]
    with pytest.raises(KeyError):
        table["three"]
    with pytest.raises(KeyError):
        del table["three"]
    table["one"] = 10  # assignment replaces, as a dict's does
    copy = table.copy()
    copy.register("three", 3)
    del copy["one"]
    assert dict(table) == {"one": 10, "two": 2} and dict(copy) == {"two": 2, "three": 3}
    assert copy.what == "widget" and copy.error is PlantedError


REGISTER_FUNCTIONS = (policies.register_policy, stages.register_dra, stages.register_sg, samplers.register_sampler,
                      tasks.register, backends.register_backend, failure_types.register_failure_type,
                      monitors.register_detector)


@pytest.mark.parametrize("function", REGISTER_FUNCTIONS, ids=lambda function: function.__name__)
def test_every_register_function_takes_overwrite_after_what_it_registers(function):
    parameters = inspect.signature(function).parameters
    assert "overwrite" in parameters and parameters["overwrite"].default is False
    before = list(parameters)[:list(parameters).index("overwrite")]
    assert before and before[0] in ("name", "kind", "row", "detector")


def _task_a(task):
    return {}


def _task_b(task):
    return {}


def test_every_register_function_refuses_a_clash_and_replaces_with_overwrite(monkeypatch):
    monkeypatch.setattr(policies, "_REGISTRY", policies._REGISTRY.copy())
    monkeypatch.setattr(stages, "_DRA_REGISTRY", stages._DRA_REGISTRY.copy())
    monkeypatch.setattr(stages, "_SG_REGISTRY", stages._SG_REGISTRY.copy())
    monkeypatch.setattr(samplers, "_REGISTRY", samplers._REGISTRY.copy())
    monkeypatch.setattr(tasks, "_KINDS", tasks._KINDS.copy())
    monkeypatch.setattr(backends, "_FACTORIES", backends._FACTORIES.copy())
    cases = [(policies.register_policy, "rule", PolicyError, lambda name: policies._REGISTRY[name]),
             (stages.register_dra, "bev", PipelineError, lambda name: stages._DRA_REGISTRY[name].call),
             (stages.register_sg, "rules", PipelineError, lambda name: stages._SG_REGISTRY[name].call),
             (samplers.register_sampler, "halton", MiningError, lambda name: samplers._REGISTRY[name]),
             (backends.register_backend, "local", WorkerError, backends.backend_factory)]
    for register, name, error, read in cases:
        replacement = samplers._REGISTRY["random"] if register is samplers.register_sampler else _task_a
        with pytest.raises(error, match=f"'{name}' is already registered; pass overwrite=True"):
            register(name, replacement)
        register(name, replacement, overwrite=True)
        assert read(name) is replacement, register.__name__
    tasks.register("probe", _task_a)
    with pytest.raises(WorkerError, match="registered twice.*pass overwrite=True"):
        tasks.register("probe", _task_b)
    assert tasks.register("probe", _task_b, overwrite=True) is _task_b
    assert tasks.function_for({"kind": "probe"}) is _task_b


def test_a_failure_type_and_its_detector_are_replaced_only_with_overwrite():
    row = FailureType("registry_probe", severity=90, result_field=None, regress_default=False, with_actor=False,
                      label=None)
    first = monitors.Detector("registry_probe", lambda result, trace, settings: None, lambda *args: -0.1)
    second = monitors.Detector("registry_probe", lambda result, trace, settings: None, lambda *args: -0.2)
    failure_types.register_failure_type(row, module="my_probe_plugins")
    try:
        with pytest.raises(FailureTypeError, match="'registry_probe' exists already; pass overwrite=True"):
            failure_types.register_failure_type(row)
        moved = FailureType("registry_probe", severity=91, result_field=None, regress_default=False,
                            with_actor=False, label=None)
        failure_types.register_failure_type(moved, module="my_probe_plugins", overwrite=True)
        assert failure_types.failure_type("registry_probe") is moved and "my_probe_plugins" in plugin_modules()
        with pytest.raises(FailureTypeError, match="'collision' exists already .a row of FAILURE_TABLE"):
            failure_types.register_failure_type(FailureType("collision", severity=92, result_field=None,
                                                            regress_default=False, with_actor=False, label=None),
                                                overwrite=True)
        monitors.register_detector(first)
        with pytest.raises(FailureTypeError, match="has a detector already; pass overwrite=True"):
            monitors.register_detector(second)
        assert monitors.register_detector(second, overwrite=True) is second
        assert monitors.DETECTORS["registry_probe"] is second
        monitors.unregister_detector("registry_probe")
        assert "registry_probe" not in monitors.DETECTORS
    finally:
        if "registry_probe" in monitors.DETECTORS:
            monitors.unregister_detector("registry_probe")
        failure_types.unregister_failure_type("registry_probe")
    assert failure_types.failure_type("registry_probe") is None and "my_probe_plugins" not in plugin_modules()


def test_replacing_or_removing_a_built_in_entry_warns_naming_it():
    table = _registry()
    table.register("three", 3)
    with pytest.warns(BuiltInReplacedWarning, match=r"the built-in widget 'one' was replaced by my_plugins"):
        table.register("one", 10, overwrite=True, module="my_plugins")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", BuiltInReplacedWarning)
        table.register("three", 30, overwrite=True)  # a plug-in's own entry: no warning
        table.register("one", 11, overwrite=True)  # replaced already: said once
        table.unregister("three")
    with pytest.warns(BuiltInReplacedWarning, match=r"the built-in widget 'two' was removed"):
        table.unregister("two")
    assert not table.is_built_in("one") and not table.is_built_in("two")


@pytest.mark.parametrize("read, name", [
    (lambda: policies._REGISTRY, "rule"), (lambda: monitors.DETECTORS, "collision"),
    (lambda: stages._SG_REGISTRY, "rules"), (lambda: stages._DRA_REGISTRY, "bev"),
    (lambda: samplers._REGISTRY, "random"), (lambda: backends._FACTORIES, "local")])
def test_the_product_registries_hold_their_own_entries_as_built_in(read, name):
    table = read().copy()
    assert table.is_built_in(name)
    with pytest.warns(BuiltInReplacedWarning, match=f"'{name}' was replaced"):
        table.register(name, table[name], overwrite=True)


def test_dv2s_says_when_a_plugin_replaces_the_collision_detector(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    (tmp_path / "noop_collision.py").write_text(
        "from dv2s_gym.mining.monitors import DETECTORS, Detector, register_detector\n"
        "register_detector(Detector('collision', lambda result, trace, settings: None, "
        "DETECTORS['collision'].score), overwrite=True)\n")
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "DV2S_PLUGINS": "noop_collision",
           "PYTHONPATH": os.pathsep.join([str(tmp_path), str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "bank", "stats"], env=env, capture_output=True,
                          text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert ("dv2s: warning: the built-in detector 'collision' was replaced by noop_collision: what runs as "
            "'collision' is not dv2s-gym's own" in done.stderr)


def test_a_worker_imports_a_plug_in_that_replaces_a_built_in_without_saying_it_again(tmp_path, monkeypatch):
    """The process that starts the workers prints the replacement once (``dv2s: warning:``); each worker imports
    the same plug-in and stays quiet, while the replacement itself holds there."""
    import sys
    import warnings

    from dv2s_gym.workers.tasks import start_plugins

    (tmp_path / "replacing_widget_plugin.py").write_text(
        "from scenario_bank.named_registry import Registry\n"
        "TABLE = Registry('widget', LookupError, {'one': 1})\n"
        "TABLE.register('one', 10, overwrite=True, module='replacing_widget_plugin')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.warns(BuiltInReplacedWarning):  # in the process that loads it first
        __import__("replacing_widget_plugin")
    del sys.modules["replacing_widget_plugin"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", BuiltInReplacedWarning)
        start_plugins(["replacing_widget_plugin"])
    assert sys.modules.pop("replacing_widget_plugin").TABLE["one"] == 10
