"""The failure types are one table (scenario_bank.failure_types): every reader takes them from it, and no other
module lists them again."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import List

import pytest

from dv2s_gym.mining import html as mining_html
from dv2s_gym.mining import monitors
from dv2s_gym.mining import report as mining_report
from dv2s_gym.mining.tasks import reference_avoids
from dv2s_gym.regress import failures
from dv2s_gym.regress import report as regress_report
from envs.safety_metrics import MonitorSettings
from envs.trace import EpisodeTrace
from policies.evaluation import EpisodeResult
from scenario_bank.records import Failure, RegressEpisode
from scenario_bank.failure_types import (FAILURE_TABLE, FAILURE_TYPES, FailureType, failure_table, failure_type,
                                         is_contact, is_near_miss, is_standstill, register_failure_type, severity_order,
                                         unregister_failure_type)
from tests.test_mining_report import make_run

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenario_bank", "envs", "policies", "dv2s_gym")
TABLE = ROOT / "scenario_bank" / "failure_types.py"


def test_the_table_is_in_severity_order_and_its_names_are_unique():
    assert [row.severity for row in FAILURE_TABLE] == list(range(len(FAILURE_TABLE)))
    assert FAILURE_TYPES == ("collision", "off_road", "low_ttc", "stall")
    assert failure_type("stall").result_field == "stalled" and failure_type("nothing") is None
    assert severity_order(["stall", "weird", "collision", "stall", "another"]) == [
        "collision", "stall", "another", "weird"]


def test_the_public_names_are_the_table_read_by_each_part():
    assert monitors.FAILURE_TYPES is FAILURE_TYPES
    assert mining_report.FAILURE_ORDER is FAILURE_TYPES
    assert failures.failure_kinds() == {"collision": "collided", "off_road": "off_road", "stall": "stalled"}
    assert list(failures.failure_kinds()) == [n for n in FAILURE_TYPES if n != "low_ttc"]  # severity order
    assert failures.default_failure() == ("collision", "off_road", "stall")
    assert [key for key, _ in regress_report.rates()] == [
        "collision_rate", "off_road_rate", "stall_rate", "failure_rate", "success_rate"]


def test_the_readers_order_by_the_table():
    assert reference_avoids(Failure("collision"), Failure("stall"))  # a stall is less severe
    assert not reference_avoids(Failure("stall"), Failure("off_road"))
    result = failures.apply_failure({"collided": False, "off_road": True, "stalled": True}, ["off_road", "stall"])
    assert result["failure_kinds"] == ["off_road", "stall"] and result["failed"]
    assert failures.parse_failure("stall,collision") == ["collision", "stall"]


def _failure_name_lists(source: str, where: str) -> List[str]:
    """Tuples, lists and sets of two or more failure names, and dicts keyed by them only, in a module's source."""
    names = set(FAILURE_TYPES)
    found = []
    for node in ast.walk(ast.parse(source, where)):
        items = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else \
            node.keys if isinstance(node, ast.Dict) else None
        if items and len(items) >= 2 and all(isinstance(i, ast.Constant) and i.value in names for i in items):
            found.append(f"{where}:{node.lineno}: {ast.unparse(node)[:80]}")
    return found


def test_no_module_but_the_table_lists_the_failure_types():
    """A second list of the failure types drifts from the table: read the table (its rows, FAILURE_TYPES,
    or regress's failure_kinds() / default_failure()) instead."""
    planted = 'ORDER = ("collision", "off_road")\nFIELDS = {"stall": "stalled", "low_ttc": None}\n'
    assert len(_failure_name_lists(planted, "planted.py")) == 2  # the check sees such lists
    assert not _failure_name_lists('MEASURES = ("collision", "success")\n', "measures.py")  # other names mixed in
    found = [hit for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py")) if path != TABLE
             for hit in _failure_name_lists(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))]
    assert not found, "failure types listed outside scenario_bank/failure_types.py:\n" + "\n".join(found)


def test_every_row_has_a_detector_and_every_detector_a_row():
    """The miner detects each failure type through its row's detector (a row without one would never be found)."""
    assert sorted(monitors.DETECTORS) == sorted(FAILURE_TYPES)
    assert all(name == detector.name for name, detector in monitors.DETECTORS.items())


TOY = "hard_brake"
"""A failure type a plug-in adds at run time: the ego slowed by more than 4 m/s in one step."""


def _hard_brake(result, trace, settings):
    speeds = [float(step["ego"][3]) for step in trace.states]
    for step in range(1, len(speeds)):
        if speeds[step - 1] - speeds[step] > 4.0:
            return monitors.Failure(TOY, step / 5.0, step, speed=speeds[step])
    return None


@pytest.fixture
def toy_type():
    """The toy type registered in one place (its row, with its label, and its detector); undone after."""
    row = register_failure_type(FailureType(TOY, severity=len(FAILURE_TABLE), result_field="hard_braked",
                                            regress_default=False, with_actor=False, label="hard brake"))
    monitors.register_detector(monitors.Detector(TOY, _hard_brake, lambda result, failure, settings: -0.25))
    yield row
    monitors.unregister_detector(TOY)
    unregister_failure_type(TOY)


def _episode(speeds, **result):
    values = dict(scenario="s", seed=0, scene_seed=0, params={}, collided=False, collisions=[], off_road=False,
                  success=True, min_ttc=math.inf, mean_speed=10.0, distance=100.0, episode_return=0.0, steps=0,
                  trajectory_hash="h", error=None)
    values.update(result)
    trace = EpisodeTrace(scenario="s", source="test", seed=0, scene_seed=0, params={}, config={"policy_frequency": 5},
                         states=[{"ego": [2.0 * i, 0.0, 0.0, v]} for i, v in enumerate(speeds)], events=[],
                         kinds={"ego": "ego"})
    return EpisodeResult(**values), trace


def test_a_failure_type_registered_in_one_place_is_detected_scored_and_counted(toy_type, tmp_path):
    assert failure_type(TOY) is toy_type and failure_table()[-1] is toy_type
    result, trace = _episode([10.0, 10.0, 4.0, 4.0, 4.0])
    failure = monitors.detect_failure(result, trace)
    assert (failure.type, failure.step, failure.speed) == (TOY, 2, 4.0)
    assert monitors.robustness(result, failure) == -0.25
    # the table's order of precedence: a more severe failure of the same episode wins
    collided, _ = _episode([10.0, 4.0], collided=True, collisions=["car1"])
    assert monitors.detect_failure(collided, trace).type == "collision"
    assert monitors.detect_failure(*_episode([10.0, 9.0, 8.0])) is None  # gentle braking is no failure
    # avoidability reads the table: the reference driver's hard brake is less severe than a stall, and its stall
    # where the policy braked hard is not
    assert reference_avoids(Failure("stall"), Failure(TOY)) and not reference_avoids(Failure(TOY), Failure("stall"))
    # counted: the mining report's failures by type, in the table's order
    run = make_run(tmp_path / "run", clips=False)
    episodes = run / "episodes.jsonl"
    episodes.write_text(episodes.read_text(encoding="utf-8").replace('"type": "stall"', f'"type": "{TOY}"'),
                        encoding="utf-8")
    report = mining_report.build_report(run)
    counts = report.to_dict()["counts"]["failures_by_type"]
    assert counts == {"collision": 5, "off_road": 3, "low_ttc": 1, TOY: 1}
    assert list(counts) == [row.name for row in failure_table() if row.name in counts]
    # shown by its row's label, counted from the table like every type (no type is named by the report itself)
    shown = "collision 5, off road 3, low_ttc 1, hard brake 1"
    assert f"Failures by type: {shown}" in mining_report.markdown(report)
    assert f"with a failure; by type: {shown}" in mining_report.format_summary(report)
    assert "Failures by type: " + shown in mining_html._counts_table(report)


@pytest.mark.parametrize("severity", [-1, 1.5, True])
def test_a_failure_type_with_a_negative_or_fractional_severity_is_refused(severity):
    with pytest.raises(ValueError, match="not a whole number >= 0"):
        register_failure_type(FailureType(TOY, severity=severity, result_field=None, regress_default=False,
                                          with_actor=False, label=None))
    assert failure_type(TOY) is None


def test_mining_refuses_to_start_with_a_type_registered_without_a_detector(tmp_path):
    """Not an error in every episode: one line before any work, naming what to call."""
    from dv2s_gym.mining.errors import MiningError
    from tests.mining_helpers import mine

    register_failure_type(FailureType(TOY, severity=len(FAILURE_TABLE), result_field=None, regress_default=False,
                                      with_actor=False, label="hard brake"))
    try:
        with pytest.raises(MiningError) as refused:
            mine("rule", out=tmp_path / "run", budget=1)
    finally:
        unregister_failure_type(TOY)
    message = str(refused.value)
    assert TOY in message and "register_detector" in message and "\n" not in message
    assert not (tmp_path / "run" / "episodes.jsonl").exists()


def test_a_registered_type_is_in_the_table_while_registered(toy_type):
    assert TOY in [row.name for row in failure_table()]


def test_registration_is_undone():
    assert failure_type(TOY) is None and TOY not in monitors.DETECTORS and failure_table() == FAILURE_TABLE


def _regress_task(monkeypatch, speeds, failure):
    """The regress worker task on a stand-in episode of ``speeds`` (no simulator), run in this process."""
    from dv2s_gym.regress import tasks
    monkeypatch.setattr(tasks.worker_cache, "env_for", lambda bank_dir, config: (("bank", "config"), None))
    monkeypatch.setattr(tasks.worker_cache, "policy_for", lambda *args, **kwargs: None)
    monkeypatch.setattr(tasks, "run_episode", lambda env, policy, scenario, seed: _episode(speeds))
    return tasks.run_regress_task({"kind": "regress", "policy": "rule", "role": "candidate", "scenario": "s",
                                   "seed": 0, "env_config": {}, "bank_dir": None, "trace_dir": None,
                                   "failure": failure, "monitor": MonitorSettings(stall_seconds=5.0)}).to_dict()


def test_regress_counts_a_registered_failure_type(toy_type, monkeypatch):
    """``dv2s regress`` reads the live table: a registered type with a result field is a --failure kind, its
    worker task records the field by the type's detector, and the report counts it."""
    assert failures.parse_failure("hard-brake,collision") == ["collision", TOY]
    assert failures.default_failure() == ("collision", "off_road", "stall")  # the toy type is not a default
    assert failures.failure_kinds()[TOY] == "hard_braked"
    braked = _regress_task(monkeypatch, [10.0, 10.0, 4.0, 4.0], ["collision", TOY])
    gentle = _regress_task(monkeypatch, [10.0, 9.0, 8.0, 7.0], ["collision", TOY])
    assert braked["error"] is None and braked["hard_braked"] is True and gentle["hard_braked"] is False
    assert braked["failed"] and braked["failure_kinds"] == [TOY] and not gentle["failed"]
    not_chosen = _regress_task(monkeypatch, [10.0, 10.0, 4.0, 4.0], ["collision"])
    assert not_chosen["hard_braked"] is True and not not_chosen["failed"]  # recorded, counted only when chosen
    summary = regress_report.summarize([RegressEpisode.from_dict(r) for r in (braked, gentle, gentle, gentle)])
    assert summary.to_dict()["hard_brake_rate"]["count"] == 1 and summary.to_dict()["failure_rate"]["count"] == 1
    assert [key for key, _ in regress_report.rates()][:4] == [
        "collision_rate", "off_road_rate", "stall_rate", "hard_brake_rate"]


def test_a_worker_without_the_registered_type_says_so(toy_type, monkeypatch):
    """A worker process where the plug-in did not register gives an error result naming the type."""
    monkeypatch.setattr(failures, "failure_table", lambda: FAILURE_TABLE)  # as a process that never registered
    result = _regress_task(monkeypatch, [10.0, 10.0, 4.0], ["collision", TOY])
    assert result.get("failed") is None and "hard_brake is not registered in this worker process" in result["error"]


def test_every_collision_type_has_a_label_and_a_kind_reads_as_words():
    from dv2s_gym.mining.monitors import COLLISION_LABELS, COLLISION_TYPES, kind_label

    assert set(COLLISION_LABELS) == set(COLLISION_TYPES)
    assert kind_label("collision:head_on") == "head-on collision"
    assert kind_label("collision:pedestrian") == "collision with a pedestrian"
    assert kind_label("off_road") == "off road" and kind_label("stall") == "stall"
    assert kind_label("collision:t_bone") == "collision (t bone)"  # a refinement no table names
    assert kind_label("wobble") == "wobble"  # a type of a plug-in not loaded now


def test_what_kind_of_failure_each_built_in_type_is():
    """The facts the conversion reads (contact, standstill, near miss) are the built-in rows'; a name that is no
    failure type has none."""
    assert [row.name for row in FAILURE_TABLE if row.contact] == ["collision"]
    assert [row.name for row in FAILURE_TABLE if row.standstill] == ["stall"]
    assert [row.name for row in FAILURE_TABLE if row.near_miss] == ["low_ttc"]
    assert is_contact("collision") and is_standstill("stall") and is_near_miss("low_ttc")
    assert not any(check(name) for check in (is_contact, is_standstill, is_near_miss) for name in ("off_road", "x", None))


def _kind_of_failure(name: str, severity: int, **facts) -> FailureType:
    return FailureType(name, severity=severity, result_field=None, regress_default=False, with_actor=True, label=None,
                       **facts)


def test_a_plug_in_type_declares_what_kind_of_failure_it_is():
    """A plug-in type that says it is a contact, a standstill or a near miss is treated as the built-in type of that
    kind is, where the miner and the conversion treat one specially; without the fact it is not."""
    from dv2s_gym.mining.behaviour import extract_behaviour, involved_actor
    from dv2s_gym.mining.conversion.episodes import reference_failed, same_failure_class

    base = len(FAILURE_TABLE) + 60
    rows = [_kind_of_failure("bump", base, contact=True), _kind_of_failure("blocked", base + 1, standstill=True),
            _kind_of_failure("close_pass", base + 2, near_miss=True), _kind_of_failure("plain", base + 3)]
    for row in rows:
        register_failure_type(row)
    try:
        assert not same_failure_class(Failure("bump", collision_type="side"), Failure("bump", collision_type="head_on"))
        assert same_failure_class(Failure("plain", collision_type="side"), Failure("plain", collision_type="head_on"))
        # the reference's near miss fails the scenario only when the policy's failure was no more severe
        assert not reference_failed(Failure("collision"), Failure("close_pass"))
        assert reference_failed(Failure("collision"), Failure("plain"))
        ahead = EpisodeTrace(scenario="s", source="test", seed=0, scene_seed=0, params={},
                             config={"policy_frequency": 5}, events=[], kinds={"ego": "ego", "lead": "car"},
                             states=[{"ego": [0.0, 0.0, 0.0, 0.0], "lead": [8.0, 0.0, 0.0, 0.0]}] * 3)
        assert involved_actor(ahead, Failure("blocked", step=2)) == "lead"
        assert involved_actor(ahead, Failure("plain", step=2)) is None
        # a contact's behaviour is read one state before it: the state at the impact has lost its speed
        moving = EpisodeTrace(scenario="s", source="test", seed=0, scene_seed=0, params={},
                              config={"policy_frequency": 5}, events=[], kinds={"ego": "ego"},
                              states=[{"ego": [2.0 * i, 0.0, 0.0, 10.0]} for i in range(11)]
                              + [{"ego": [21.0, 0.0, 0.0, 0.0]}])
        assert extract_behaviour(moving, Failure("bump", step=11)).ego_manoeuvre == "keeping_lane"
        assert extract_behaviour(moving, Failure("plain", step=11)).ego_manoeuvre == "stopped"
    finally:
        for row in rows:
            unregister_failure_type(row.name)


FAILURE_COMPARISONS_ALLOWED = {
    ("dv2s_gym/mining/monitors.py", "kind_label", "collision"):
        "COLLISION_LABELS are the words of the built-in collision's own refinement (its collision types, "
        "'rear-end collision'); another type's refinement read through them would be called a collision",
    ("dv2s_gym/regress/runner.py", "_check_env_config", "stall"):
        "--stall-seconds is the setting of the built-in stall detector: a stall-seconds not shorter than the episodes "
        "makes that type undetectable when --failure counts it",
    ("dv2s_gym/regress/runner.py", "_baseline_from_report", "stall"):
        "the baseline report records the built-in stall detector's stall-seconds: compared when --failure counts "
        "that type",
}
"""Comparisons with a built-in failure type's name that stay, by (module, function, name), with the reason."""

EVENT_KINDS = frozenset({"collision", "off_road"})
"""The trace's event kinds that are also failure types' names (the simulator's ``collision``, the env's
``off_road`` event): comparing an event's kind with them reads the trace's vocabulary, not the failure table."""


def _reads_event_kind(node: ast.AST) -> bool:
    """``x["kind"]`` or ``x.get("kind")``: a trace event's kind."""
    if isinstance(node, ast.Subscript):
        return isinstance(node.slice, ast.Constant) and node.slice.value == "kind"
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
            and bool(node.args) and isinstance(node.args[0], ast.Constant) and node.args[0].value == "kind")


def _spelled_names(node: ast.AST) -> List[str]:
    """The built-in failure-type names ``node`` spells: a string, or a tuple, list or set of strings."""
    items = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else [node]
    return [item.value for item in items if isinstance(item, ast.Constant) and item.value in FAILURE_TYPES]


def _failure_name_comparisons(source: str, where: str) -> List[tuple]:
    """``(where, function, name, line)`` of every ``==``, ``!=``, ``in``, ``not in`` with a built-in failure-type
    name in a module's source, but an event's kind compared with an event kind."""
    found = []

    def visit(node: ast.AST, function: str) -> None:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            function = node.name
        if isinstance(node, ast.Compare):
            operands = [node.left] + list(node.comparators)
            for op, left, right in zip(node.ops, operands, operands[1:]):
                if not isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)):
                    continue
                for name_side, other in ((left, right), (right, left)):
                    for name in _spelled_names(name_side):
                        if not (name in EVENT_KINDS and _reads_event_kind(other)):
                            found.append((where, function, name, node.lineno))
        for child in ast.iter_child_nodes(node):
            visit(child, function)

    visit(ast.parse(source, where), "<module>")
    return found


def test_no_product_comparison_spells_a_built_in_failure_type():
    """A branch on a built-in type's name leaves a plug-in type out: read the row's facts (``with_actor``,
    ``contact``, ``standstill``, ``near_miss``, ``result_field``) instead. The comparisons that stay are
    :data:`FAILURE_COMPARISONS_ALLOWED`, each with its reason."""
    planted = ('def f(failure, event, kind):\n    stall = failure.type == "stall"\n'
               '    if kind in ("low_ttc", "x"):\n        pass\n    if event.get("kind") == "collision":\n'
               '        pass\n    if event["kind"] == "stall" or "off_road" != kind:\n        pass\n')
    assert [(name, line) for _, function, name, line in _failure_name_comparisons(planted, "planted.py")] == [
        ("stall", 2), ("low_ttc", 3), ("stall", 7), ("off_road", 7)]  # an event's collision kind is not one
    found = [hit for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))
             for hit in _failure_name_comparisons(path.read_text(encoding="utf-8"), path.relative_to(ROOT).as_posix())]
    unexplained = [f"{where}:{line} ({function}): {name!r}" for where, function, name, line in found
                   if (where, function, name) not in FAILURE_COMPARISONS_ALLOWED]
    assert not unexplained, ("comparisons with a built-in failure type's name (read the row's facts, or allow one "
                             "with its reason):\n" + "\n".join(unexplained))
    stale = set(FAILURE_COMPARISONS_ALLOWED) - {(where, function, name) for where, function, name, _ in found}
    assert not stale, f"allowed comparisons that are gone: {sorted(stale)}"
