"""The mining modules that read episode records pass typed records to each other, not string-keyed dicts.

The loop's rounds are typed to the step: each step of ``loop.json`` (``RoundSteps``) is a frozen record of
``dv2s_gym.loop.record`` (``MiningSummary`` with its ``MinedEntry`` list, ``SplitRecord``, ``ReferenceGate``,
``HeldOutBefore``, ``FineTuneArm``, ``HeldOutComparison``, ``UntouchedComparison``, ``RegressSummary``), the loop's
functions return them, and each one's ``to_dict`` writes back exactly the JSON object it was read from.

The modules of :data:`TYPED_MODULES` read a run's episodes as :class:`scenario_bank.records.EpisodeRecord` (by
their fields) and hand each other frozen records (``Behaviour``, ``FailureEntry``, ``ClusterEntry``,
``RateEstimate``, ``FailureRate``, ``FamilyGroup``, ``FamilySplit``); their JSON form, the one the files hold, is
each record's ``to_dict``. No public function of theirs takes or returns a ``Dict[str, Any]`` or
``Mapping[str, Any]`` (or a bare ``dict``) unless :data:`JSON_BOUNDARIES` lists it with the reason: the ones that
read or write a file format, or take a structure another module owns that has no typed record yet. The modules are
parsed, not imported.

The miner runs on its typed settings and tasks: :class:`~dv2s_gym.mining.settings.MineSettings` (``MineRun.settings``
too), :class:`~dv2s_gym.mining.tasks.MineTask` per episode (its JSON object only where a pool ships it) and
:class:`~dv2s_gym.mining.settings.RunOrigin`; ``settings.json`` is written from them and read back only to check a
resumed run's identity.

A typed record is no mapping (:func:`test_a_typed_record_is_no_mapping`): it is read by its fields, and its JSON object
is its ``to_dict``.
"""

from __future__ import annotations

import ast
import copy
import textwrap
from pathlib import Path
import json
import typing
from typing import Dict, List

import pytest

from scenario_bank.records import JsonRecord

ROOT = Path(__file__).resolve().parents[1]
DV2S_GYM = ROOT / "dv2s_gym"

TYPED_MODULES = ("mining.behaviour", "mining.cluster", "mining.family", "mining.sampling.rate", "mining.report",
                 "mining.report_record", "mining.html", "mining.conversion.record", "mining.miner", "loop.split",
                 "loop.run", "loop.state", "loop.steps", "loop.mined", "loop.arms", "loop.measures", "loop.comparisons",
                 "loop.record", "loop.report", "loop.report_text", "loop.html", "loop.verdict")
"""The modules of the miner and the loop (under ``dv2s_gym``) whose functions pass typed records."""

JSON_BOUNDARIES: Dict[str, str] = {
    "mining.report.read_jsonl": "reads the JSON objects of a run's .jsonl files: the file format",
    "mining.report.build_report_from_records": "takes the run's settings.json as recorded (RunSettings.values)",
    "mining.sampling.rate.rate_estimates": "takes the run's settings.json as recorded (RunSettings.values)",
    "loop.run.LoopReport.to_json": "returns the body of report.json, built at the point it is written",
    "loop.comparisons.untouched_settings": "takes the policy's env config, a JSON object of its model card",
}
"""``"module.function"`` of the typed modules that take or return a JSON object, each with the reason. A record's
``to_dict`` (its JSON form) needs no entry."""

EPISODE_READERS = {
    "mining.behaviour.behaviour_of": "record", "mining.family.record_family": "record", "mining.cluster.cluster_id": "record",
    "mining.cluster.cell_id": "record", "mining.cluster.pair_of": "record", "mining.cluster.cluster_failures": "records",
    "mining.cluster.group": "records", "mining.sampling.rate.failure_rate": "records", "mining.sampling.rate.rate_estimates": "records",
    "mining.report.build_report_from_records": "episodes",
}
"""``"module.function": parameter`` of the functions that read episode records: each is annotated with
:class:`~scenario_bank.records.EpisodeRecord`."""

_JSON_TYPES = ("Dict[str, Any]", "Mapping[str, Any]", "dict[str, Any]")


def _is_json_object(annotation: ast.expr | None) -> bool:
    """Whether an annotation names a string-keyed JSON object (anywhere in it: ``List[Dict[str, Any]]`` too)."""
    if annotation is None:
        return False
    text = ast.unparse(annotation).replace("typing.", "").strip("'\"")
    return any(name in text for name in _JSON_TYPES) or text in ("dict", "Dict", "Mapping")


def _public_functions(tree: ast.Module) -> Dict[str, ast.FunctionDef]:
    """``{"function" | "Class.method": node}`` of a module's public functions and its public classes' public
    methods."""
    found: Dict[str, ast.FunctionDef] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            found[node.name] = node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and not item.name.startswith("_"):
                    found[f"{node.name}.{item.name}"] = item
    return found


def json_object_functions(source: str) -> List[str]:
    """The public functions of a module's ``source`` that take or return a JSON object (but a ``to_dict``)."""
    found = []
    for name, node in _public_functions(ast.parse(source)).items():
        if name.endswith(".to_dict"):
            continue
        arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
        arguments += [a for a in (node.args.vararg, node.args.kwarg) if a is not None]
        if _is_json_object(node.returns) or any(_is_json_object(a.annotation) for a in arguments):
            found.append(name)
    return found


def _source(module: str) -> str:
    return (DV2S_GYM / (module.replace(".", "/") + ".py")).read_text(encoding="utf-8")


def test_the_check_sees_a_json_object_taken_or_returned():
    planted = textwrap.dedent("""
        from typing import Any, Dict, List, Mapping, Optional

        def takes(record: Dict[str, Any]) -> int: ...
        def returns(n: int) -> Optional[Mapping[str, Any]]: ...
        def in_a_list(*rows: List[Dict[str, Any]]) -> None: ...
        def bare(row: dict) -> None: ...
        def typed(row: "EpisodeRecord") -> Dict[str, int]: ...
        def _private(row: Dict[str, Any]) -> None: ...

        class Record:
            def to_dict(self) -> Dict[str, Any]: ...
            def named(self, *, extra: Mapping[str, Any] = None) -> str: ...
    """)
    assert json_object_functions(planted) == ["takes", "returns", "in_a_list", "bare", "Record.named"]


def test_the_typed_modules_pass_typed_records():
    found = [f"{module}.{name}" for module in TYPED_MODULES for name in json_object_functions(_source(module))]
    unlisted = [name for name in found if name not in JSON_BOUNDARIES]
    assert not unlisted, (f"{unlisted} take or return a string-keyed dict; pass a typed record (EpisodeRecord or a "
                          "frozen record of the module that owns it, with to_dict for its JSON form), or list it in "
                          "JSON_BOUNDARIES with the reason")
    stale = sorted(set(JSON_BOUNDARIES) - set(found))
    assert not stale, f"{stale} no longer take or return a JSON object: remove them from JSON_BOUNDARIES"


def test_the_functions_that_read_episodes_take_episode_records():
    untyped = []
    for qualified, parameter in EPISODE_READERS.items():
        module, name = qualified.rsplit(".", 1)
        node = _public_functions(ast.parse(_source(module)))[name]
        annotation = next(a.annotation for a in node.args.args + node.args.kwonlyargs if a.arg == parameter)
        if "EpisodeRecord" not in ast.unparse(annotation):
            untyped.append(f"{qualified}({parameter}: {ast.unparse(annotation)})")
    assert not untyped, f"{untyped} read episode records: annotate them EpisodeRecord and read their fields"


def _step_records() -> Dict[str, type]:
    from dv2s_gym.loop import record as loop_record

    hints = typing.get_type_hints(loop_record.RoundSteps, vars(loop_record))
    return {step: hints[step] for step in loop_record.STEPS}


def test_every_step_of_a_round_is_a_typed_record():
    untyped = []
    for step, hint in _step_records().items():
        kinds = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(kinds) != 1 or not (isinstance(kinds[0], type) and issubclass(kinds[0], JsonRecord)):
            untyped.append(f"{step}: {hint}")
    assert not untyped, f"steps {untyped} of a round are not typed records (loop_record.RoundSteps)"


def test_the_mined_entries_are_typed_records():
    from dv2s_gym.loop import record as loop_record
    from dv2s_gym.loop.mined import mined_entries
    from dv2s_gym.loop.replays import replay_entries
    from dv2s_gym.loop.split import family_of, family_groups, split_by_family

    hints = typing.get_type_hints(loop_record.MiningSummary, vars(loop_record))
    assert typing.get_args(typing.get_args(hints["kept"])[0]) == (loop_record.MinedEntry, Ellipsis)
    for function in (mined_entries, replay_entries):
        assert "MinedEntry" in str(typing.get_type_hints(function)["return"]), function.__name__
    for function, parameter in ((family_of, "entry"), (family_groups, "entries"), (split_by_family, "entries")):
        assert "MinedEntry" in str(typing.get_type_hints(function)[parameter]), function.__name__


_ROUND = {
    "round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:/x/round_1/policy/model.zip", "timings": {"mine": 1.5},
    "steps": {
        "mine": {"episodes": 4, "errors": 0, "errored": {"episodes": 0, "scenarios": {}, "messages": {}},
                 "failures": 2, "failures_against_policy": 1, "clusters": None, "conversions": {"kept": 1},
                 "replays": {}, "rejected_reasons": ["judge: no"], "rejected_reason_count": 1,
                 "clusters_not_converted": None, "clusters_not_kept": None, "clusters_reference_failed": None,
                 "kept": [{"cluster": "a/collision/r0", "scenario": "a_m1", "reproduction": None},
                          {"cluster": "b/stall/r0", "scenario": "b_r1", "parent": None, "reproduction": None,
                           "replay": True, "not_narrowed": {"speed": "categorical"}, "later": 1}],
                 "folder": "/x/round_1/mine"},
        "split": {"by": "family", "fine_tune": ["a_m1"], "held_out": ["b_r1"], "fine_tune_clusters": ["a/collision/r0"],
                  "held_out_clusters": ["b/stall/r0"], "fine_tune_families": ["a"], "held_out_families": ["b"],
                  "groups": 2, "moved_to_fine_tune": []},
        "reference": {"reference": "rule", "episodes": 2, "kept": 1, "excluded": [["b_r1", 1000]], "failed": 1,
                      "errored": 0, "by_scenario": {"b_r1": {"episodes": 2, "excluded": 1, "failures": {"stall": 1}}},
                      "excluded_families": []},
        "before": {"episodes": 1, "done": True, "errored": {"episodes": 0}},
        "fine_tune": {"model": "/x/m.zip", "method": "dagger", "scenarios": 3, "mined_upweighted": 1, "steps": 8,
                      "mined_left_out": 0, "families": ["a"], "reward_weights": None, "env_config": {},
                      "reference": None, "agreement": None, "resumed": []},
        "control": {"model": "/x/c.zip", "method": "ppo", "scenarios": 2, "mined_upweighted": 0, "steps": 8,
                    "mined_left_out": 1, "families": ["a"], "reward_weights": {"standing": -0.3}, "env_config": {}},
        "untouched": {"scenarios": ["u1"], "seeds": 2, "policies": {"start": {"episodes": 2, "failure_rate": None}},
                      "fine_tuned_vs_start": {"verdict": None, "reason": None, "episodes": None, "difference": None,
                                              "p_value": None, "report": "/x/u/report.json"},
                      "errored": {"start": {"episodes": 0}}},
        "regress": {"verdict": "PASS", "reason": "ok", "episodes": 8, "new_failure_rate": None,
                    "old_failure_rate": {"value": 0.1}, "difference": {"value": 0.0, "low": -0.1, "high": 0.1},
                    "p_value": None, "regressed": [], "report": "/x/r/report.json", "held_out_parents": {},
                    "errored": {}},
    },
}


def test_a_round_reads_into_typed_steps_and_writes_back_the_same_json():
    from dv2s_gym.loop import record as loop_record

    record = loop_record.RoundRecord.from_dict(_ROUND)
    steps = record.steps
    assert isinstance(steps.mine, loop_record.MiningSummary)
    assert [type(e) for e in steps.mine.kept] == [loop_record.MinedEntry] * 2
    assert [e.scenario for e in steps.mine.replayed] == ["b_r1"] and steps.mine.kept[1].parent is None
    assert steps.split.held_out_scenarios == ("b_r1",) and steps.reference.excluded_episodes == {("b_r1", 1000)}
    assert isinstance(steps.fine_tune, loop_record.FineTuneArm) and steps.control.reward_weights == {"standing": -0.3}
    assert steps.untouched.fine_tuned_vs_start.report == "/x/u/report.json"
    assert steps.regress.difference["high"] == 0.1 and steps.before.done is True
    written = json.dumps(record.to_dict(), sort_keys=True)
    assert written == json.dumps(_ROUND, sort_keys=True)
    # a step recorded through the loop's own path is stored as it reads back
    again = loop_record.RoundRecord.started(1).with_step("mine", steps.mine)
    assert json.dumps(again.steps.mine.to_dict(), sort_keys=True) == json.dumps(_ROUND["steps"]["mine"], sort_keys=True)


def test_the_records_the_loop_builds_write_the_json_it_wrote_as_dicts():
    from dv2s_gym.loop.record import FineTuneArm, MinedEntry, RegressComparison

    # a DAgger arm writes its reward weights, reference and agreement even when there are none; a PPO arm does not
    # write the DAgger fields at all
    dagger = FineTuneArm(model="m", method="dagger", reward_weights=None, env_config={}, reference=None,
                         agreement=None, resumed=())
    assert dagger.to_dict() == {"model": "m", "method": "dagger", "reward_weights": None, "env_config": {},
                                "reference": None, "agreement": None, "resumed": []}
    assert FineTuneArm(model="m", method="ppo", reward_weights={}).to_dict() == {"model": "m", "method": "ppo",
                                                                                 "reward_weights": {}}
    # an exact replay always records its parent and reproduction; a converted entry its reproduction
    assert MinedEntry(cluster="c", scenario="s", replay=True).to_dict() == {
        "cluster": "c", "scenario": "s", "reproduction": None, "parent": None, "replay": True}
    assert MinedEntry(cluster="c", scenario="s").to_dict() == {"cluster": "c", "scenario": "s", "reproduction": None}
    assert set(RegressComparison(report="r").to_dict()) == {"verdict", "reason", "episodes", "difference", "p_value",
                                                           "report"}


def test_the_failure_interaction_is_a_typed_record_written_as_before():
    from dv2s_gym.mining.conversion.interaction import FailureInteraction, failure_interaction, interaction_sentence

    assert "FailureInteraction" in str(typing.get_type_hints(failure_interaction)["return"])
    alone = FailureInteraction(failure_type="stall")
    # a conversion's record and a bank entry's provenance hold every field, null when unknown
    assert alone.to_dict() == {"failure_type": "stall", "actor": None, "kind": None, "manoeuvres": [], "gap_m": None,
                               "side": None}
    assert list(alone.to_dict()) == ["failure_type", "actor", "kind", "manoeuvres", "gap_m", "side"]
    recorded = {"failure_type": "collision", "actor": "car1", "kind": "car", "manoeuvres": ["brake"], "gap_m": 12.5,
                "side": "same_lane"}
    read = FailureInteraction.from_dict(recorded)
    assert read.manoeuvres == ("brake",) and read.to_dict() == recorded
    assert interaction_sentence(read) == interaction_sentence(recorded) != ""


_KEYED = ("settings", "recorded", "task", "origin")
"""Names the miner once read by string key: its settings, ``settings.json``'s content, a task and the origin."""


def keyed_reads(source: str) -> List[str]:
    """The string-key reads (``x["key"]``, ``x.get("key")``) of a value named like :data:`_KEYED` in ``source`` (a
    write, ``x["key"] = ...``, fills a file's JSON object: not a read)."""
    return [ast.unparse(node) for node, target, _ in _key_reads(ast.parse(source))
            if ast.unparse(target).split(".")[-1] in _KEYED]


def test_the_keyed_read_check_sees_settings_and_tasks_read_by_key():
    planted = textwrap.dedent("""
        def run(self, settings, task, recorded):
            recorded["schedule"] = "window"
            return settings["seed"], self.settings.get("reference"), task["index"], record["scenario"], settings.seed
    """)
    assert keyed_reads(planted) == ["settings['seed']", "self.settings.get('reference')", "task['index']"]


def test_the_miner_reads_its_settings_and_tasks_by_their_fields():
    """No setting, task field or origin is read by a string key in the miner (settings.json is written whole)."""
    assert keyed_reads(_source("mining.miner")) == []
    from dv2s_gym.mining.miner import MineRun
    from dv2s_gym.mining.settings import MineSettings

    assert typing.get_type_hints(MineRun)["settings"] is MineSettings


def test_a_mining_task_reads_back_from_the_json_a_pool_ships():
    from dv2s_gym.mining.errors import MiningError
    from dv2s_gym.mining.monitors import MonitorSettings
    from dv2s_gym.mining.tasks import MINE, MineTask

    task = MineTask(index=3, policy="rule", scenario="s", seed=41, params={"gap": 2.5}, reference="rule",
                    family="f", env_config={"duration": 3}, bank_dir="bank", trace_dir="traces",
                    monitor=MonitorSettings(ttc_threshold=1.5, stall_seconds=4.0), failure_types=("collision",))
    shipped = task.to_json()
    assert json.loads(json.dumps(shipped)) == shipped  # a plain JSON object, as any pool can ship
    assert (shipped["kind"], shipped["role"], shipped["id"]) == (MINE, "mine", "s/41")
    assert MineTask.from_json(shipped) == task
    with pytest.raises(MiningError, match="needs index, seed"):
        MineTask.from_json({"policy": "rule", "scenario": "s"})


def test_a_run_s_origin_is_recorded_as_the_json_object_the_reports_read(tmp_path):
    from dv2s_gym.mining.errors import MiningError
    from dv2s_gym.mining.miner import mine
    from dv2s_gym.mining.report_text import seed_text
    from dv2s_gym.mining.settings import MineSettings, RunOrigin

    origin = RunOrigin(command="dv2s loop", seed=4, round=2)
    assert json.dumps(origin.to_json()) == '{"command": "dv2s loop", "seed": 4, "round": 2}'
    assert RunOrigin.from_json(origin.to_json()) == origin
    assert seed_text({"seed": 4002, "origin": origin.to_json()}) == \
        "seed 4002 (derived by dv2s loop from its seed 4, round 2)"
    with pytest.raises(MiningError, match="origin round"):
        RunOrigin(command="dv2s loop", seed=4, round=0)
    with pytest.raises(MiningError, match="origin must be a RunOrigin"):
        mine("rule", MineSettings(budget=1), out=tmp_path / "run", origin={"command": "dv2s loop"})
    assert not (tmp_path / "run").exists()


def test_a_held_out_rate_is_a_rate_record_with_one_formatter():
    from dv2s_gym.loop.heldout import paired_summary
    from dv2s_gym.loop.record import PairedSummary, PairedTable
    from policies.stats import Rate
    from dv2s_gym.loop.report import rate_text
    from scenario_bank.records import HeldOutEpisode, RecordError

    before = [{"scenario": "s", "seed": seed, "failed": seed < 3, "error": None} for seed in range(4)]
    after = [{"scenario": "s", "seed": seed, "failed": seed < 1, "error": None} for seed in range(4)]
    summary = paired_summary(*([HeldOutEpisode.from_dict({"role": "before", **row}) for row in rows]
                               for rows in (before, after)))
    assert isinstance(summary, PairedSummary) and isinstance(summary.before, Rate)
    assert isinstance(summary.table, PairedTable) and summary.table.before_only == 2
    assert (summary.before.k, summary.before.n, summary.after.k) == (3, 4, 1)
    assert summary.before.text() == rate_text(summary.before) == \
        f"3/4 = 0.75 [{summary.before.low:.2f}, {summary.before.high:.2f}]"
    written = summary.to_dict()
    assert json.loads(json.dumps(written)) == written and written["before"]["rate"] == 0.75
    assert PairedSummary.from_dict(written).to_dict() == written
    empty = paired_summary([], [])
    assert empty.before.text() == rate_text(empty.before) == rate_text(None) == "-"
    assert empty.to_dict()["before"]["rate"] is None and empty.to_dict()["relative_drop"] is None
    with pytest.raises(RecordError, match="'before.k'"):
        PairedSummary.from_dict({**written, "before": {**written["before"], "k": "three"}})


def test_the_mining_report_is_a_typed_record_written_as_report_json():
    from dv2s_gym.mining.report import build_report_from_records, format_summary, markdown
    from dv2s_gym.mining.report_record import MineCounts, MineReport, SamplerSummary
    from scenario_bank.records import RecordError

    report = build_report_from_records({"policy": "p", "sampler": "random", "seed": 0}, [], [], {},
                                       created="2026-01-01T00:00:00+00:00")
    assert isinstance(report, MineReport) and isinstance(report.counts, MineCounts)
    assert all(isinstance(entry, SamplerSummary) for entry in report.samplers.values())
    assert report.counts.failures == report.to_dict()["counts"]["failures"] == 0
    saved = json.loads(json.dumps(report.to_dict(), sort_keys=True))  # as report.json holds it
    assert "run_dir" in saved and saved["run_dir"] is None  # every field is written, null included
    again = MineReport.from_dict(saved)
    assert json.dumps(again.to_dict(), sort_keys=True) == json.dumps(saved, sort_keys=True)
    assert markdown(again) == markdown(report) and format_summary(again) == format_summary(report)
    with pytest.raises(TypeError, match="markdown takes a MineReport, not dict; read a report.json with "
                                        r"MineReport.from_dict"):
        markdown(saved)  # the renderings take the record: report.json is read into one where it is read
    with pytest.raises(RecordError, match="'counts.failures'"):
        MineReport.from_dict({**saved, "counts": {**saved["counts"], "failures": "none"}})


def test_loop_json_s_settings_and_start_are_typed_records():
    from dv2s_gym.loop.record import LoopStart, RecordedLoopSettings
    from scenario_bank.records import RecordError

    settings = {"policy": "dv2s-ppo", "bank_dir": None, "workers": 2, "holdout_by": "family",
                "env_config": {"duration": 10}, "fine_tune_env_config": {}, "budget": 32, "sampler": "random"}
    record = RecordedLoopSettings.from_dict(settings)
    assert (record.policy, record.workers, record.bank_dir) == ("dv2s-ppo", 2, None)
    assert record.to_dict() == settings and record.to_dict()["budget"] == 32  # the other settings kept as recorded
    start = LoopStart.from_dict({"bank": "/b", "scenarios": ["a", "b"]})
    assert start.scenarios == ("a", "b") and start.to_dict() == {"bank": "/b", "scenarios": ["a", "b"]}
    with pytest.raises(RecordError, match="'workers'"):
        RecordedLoopSettings.from_dict({**settings, "workers": "two"})
    with pytest.raises(RecordError, match="'scenarios'"):
        LoopStart.from_dict({"bank": "/b", "scenarios": "a"})


_CONVERSION = {"cluster": "a/collision/r0", "index": 3, "status": "merged", "reason": None, "stage": None,
               "video": "failures/a/failure.webm", "description": "a car brakes", "script": None,
               "reproduction": {"k": 2, "reproduced": 1, "rate": 0.5}, "e2e_sc": 0.71, "bank_entry": None,
               "merged_into": "mined_a", "merge_reason": "near copy", "seconds": 1.5, "timings": {"video": 0.5},
               "interaction": None, "replay_entry": "replay_a", "avoidability": None, "rejections": [],
               "actors": None, "parameters": None, "converted_video": None, "later_key": [1, 2]}


def test_a_conversion_record_is_typed_with_its_status_and_writes_back_the_same_line(tmp_path):
    from dv2s_gym.mining.conversion.record import ConversionRecord, ConversionStatus, read_conversions
    from dv2s_gym.mining.jsonl import JsonlAppender
    from scenario_bank.records import RecordError

    record = ConversionRecord.from_dict(_CONVERSION)
    assert record.status is ConversionStatus.MERGED and record.merged and not record.kept and not record.rejected
    assert (record.merged_into, record.rejections, record.extra) == ("mined_a", (), {"later_key": [1, 2]})
    assert record.to_dict() == _CONVERSION
    path = tmp_path / "conversions.jsonl"
    appender = JsonlAppender(path)
    appender.append(record)
    appender.close()
    assert path.read_text() == json.dumps(_CONVERSION, sort_keys=True) + "\n"  # the line the dict wrote
    assert [r.to_dict() for r in read_conversions(path)] == [_CONVERSION]
    with pytest.raises(RecordError, match="'status' must be one of 'kept', 'merged', 'rejected', not 'lost'"):
        ConversionRecord.from_dict({**_CONVERSION, "status": "lost"})
    path.write_text(json.dumps({**_CONVERSION, "index": "three"}) + "\n")
    with pytest.raises(RecordError, match=r"conversions.jsonl, record 1: conversion record field 'index'"):
        read_conversions(path)


def test_the_mining_report_holds_its_clusters_and_failures_as_records():
    from dv2s_gym.mining.behaviour import Behaviour
    from dv2s_gym.mining.conversion.record import ConversionRecord, ConversionStatus
    from dv2s_gym.mining.report import build_report_from_records
    from dv2s_gym.mining.report_record import (ClusterEntry, FailureEntry, MineReport, RejectedConversion,
                                               ScenarioSummary)
    from scenario_bank.records import EpisodeRecord

    failed = EpisodeRecord.from_dict({
        "index": 3, "scenario": "a", "family": "a", "seed": 7, "policy": "p", "params": {"gap": 4.0},
        "sampler": "random",
        "failure": {"type": "collision", "kind": "collision:rear_end", "time": 2.0, "with": "car1",
                    "with_kind": "car", "collision_type": "rear_end"}, "avoidable": True, "rho": -1.0,
        "behaviour": {"actor": "car", "actor_manoeuvre": "braking", "ego_manoeuvre": "following"}})
    rejected = {**_CONVERSION, "cluster": "b/stall/r0", "index": 9, "status": "rejected", "stage": "check",
                "reason": "check: compile failed", "merged_into": None, "rejections": ["check: compile failed"]}
    report = build_report_from_records({"policy": "p", "sampler": "random", "scenarios": ["a"]}, [failed],
                                       [_CONVERSION, rejected], {3: "a/collision/r0"})
    (cluster,) = report.clusters
    assert isinstance(cluster, ClusterEntry) and isinstance(cluster.representative, FailureEntry)
    assert isinstance(cluster.conversion, ConversionRecord) and cluster.status == ConversionStatus.MERGED
    assert cluster.behaviour == Behaviour(actor="car", actor_manoeuvre="braking", ego_manoeuvre="following")
    assert (cluster.merged_into, cluster.representative.with_actor, cluster.scenarios) == ("mined_a", "car1", ("a",))
    assert [type(f) for f in report.failures] == [FailureEntry] and report.failures[0].seed == 7
    assert isinstance(report.scenarios["a"], ScenarioSummary) and report.scenarios["a"].failures == 1
    assert [(type(r), r.stage, r.rejections) for r in report.rejected] == [
        (RejectedConversion, "check", ("check: compile failed",))]
    saved = json.loads(json.dumps(report.to_dict(), sort_keys=True))
    assert saved["clusters"][0]["representative"]["with"] == "car1" and saved["clusters"][0]["status"] == "merged"
    assert saved["clusters"][0]["conversion"] == _CONVERSION
    assert json.dumps(MineReport.from_dict(saved).to_dict(), sort_keys=True) == json.dumps(saved, sort_keys=True)


def _record_classes() -> List[type]:
    """Every typed record class of the product (the subclasses of ``JsonRecord``), each product module whose text
    names ``JsonRecord`` or another ``...Record`` (every module that defines records does) imported first."""
    import importlib

    for package in ("scenario_bank", "envs", "policies", "dv2s_gym"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if "Record" in path.read_text() and path.name != "__main__.py" and "maps" not in path.parts:
                importlib.import_module(".".join(path.relative_to(ROOT).with_suffix("").parts).replace(".__init__", ""))
    found, todo = [], [JsonRecord]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub not in found:
                found.append(sub)
                todo.append(sub)
    return found


MAPPING_METHODS = ("__getitem__", "__iter__", "__len__", "__contains__", "keys", "get", "items", "values")
"""What a record would have if it were read by key like the JSON object it stands for."""


def test_a_typed_record_is_no_mapping():
    """A record is read by its fields; its JSON object is its ``to_dict``. No record class (the ``JsonRecord``s and
    the semantic elements' ``Elements``) is a ``Mapping`` or has a mapping's methods, so a reader that reads one by
    key fails at once instead of reading a misspelled key as ``None``."""
    from collections.abc import Mapping

    from scenario_bank.elements import Elements
    from scenario_bank.records import EpisodeRecord, Provenance, recorded

    classes = _record_classes()
    assert len(classes) > 40 and EpisodeRecord in classes  # every record module was found
    checked = classes + [JsonRecord, Elements]
    mappings = [c.__qualname__ for c in checked if issubclass(c, Mapping)]
    assert not mappings, f"typed records that are mappings: {mappings}"
    keyed = [f"{c.__qualname__}.{name}" for c in checked for name in MAPPING_METHODS if hasattr(c, name)]
    assert not keyed, f"typed records read by key: {keyed}"
    empty = Provenance.from_dict({})
    assert empty.to_dict() == {} and bool(empty) and not recorded(empty) and not recorded(None)
    episode = {"index": 0, "scenario": "s", "seed": 1}
    assert EpisodeRecord.from_dict(episode) == EpisodeRecord.from_dict(dict(episode))
    assert recorded(EpisodeRecord.from_dict(episode))
    assert EpisodeRecord.from_dict(episode) != episode and EpisodeRecord.from_dict(episode).to_dict() == episode
    with pytest.raises(TypeError):
        EpisodeRecord.from_dict(episode)["seed"]
    elements = Elements.from_dict({"road": "highway", "participants": ["ego"]})
    for read in (lambda: elements["road"], lambda: dict(elements), lambda: "road" in elements, lambda: len(elements)):
        with pytest.raises(TypeError):
            read()
    # every record is true, a record of nothing too: emptiness is tested against Elements()
    assert bool(Elements()) and Elements.from_dict({}) == Elements() and elements != Elements()


_FAILURE_KEYS = ("type", "time", "step", "with", "with_kind", "collision_type", "min_ttc", "speed", "kind", "actor",
                 "actor_manoeuvre", "ego_manoeuvre")
"""The JSON keys of a failure (:class:`~scenario_bank.records.Failure`) and a behaviour
(:class:`~scenario_bank.records.Behaviour`)."""
_HOLDERS = ("failure", "behaviour", "source_failure", "reference_failure", "ref_failure")
"""Names of the values that hold a failure or a behaviour."""
_FAILURE_READ_ALLOWED = {
    "scenario_bank/records.py": "Provenance.failure_type reads a bank entry's provenance, whose failure is kept as the "
                                "JSON object its sidecar holds",
}
"""Modules that may read a failure by key, with the reason."""


def _key_reads(tree: ast.AST):
    """``(node, target, key)`` of each string-key read in ``tree`` (``x["key"]``, ``x.get("key")``), ``target`` the
    value read with ``(x or {})`` and ``dict(x or {})`` taken as ``x``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load):
            target, key = node.value, node.slice
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get" \
                and node.args:
            target, key = node.func.value, node.args[0]
        else:
            continue
        if isinstance(key, ast.Constant) and isinstance(key.value, str):
            yield node, _unwrapped(target), key.value


def _unwrapped(target: ast.expr) -> ast.expr:
    """``x`` of ``x``, ``(x or {})``, ``dict(x)`` and ``dict(x or {})``."""
    if isinstance(target, ast.BoolOp):  # (record.failure or {}).get("type")
        target = target.values[0]
    if isinstance(target, ast.Call) and ast.unparse(target.func) == "dict" and target.args:
        target = target.args[0]  # dict(record.failure or {})
        target = target.values[0] if isinstance(target, ast.BoolOp) else target
    return target


def failure_key_reads(source: str) -> List[str]:
    """The string-key reads of a failure's or a behaviour's JSON keys (``failure["kind"]``, ``record.failure.get(
    "with")``, ``(record.behaviour or {}).get("actor")``) of a value named like :data:`_HOLDERS` in ``source``."""
    return [ast.unparse(node) for node, target, key in _key_reads(ast.parse(source))
            if ast.unparse(target).split(".")[-1] in _HOLDERS and key in _FAILURE_KEYS]


def _is_held(target: ast.expr, attribute: str, aliases: typing.AbstractSet[str]) -> bool:
    """Whether ``target`` is an episode record's ``attribute`` (``<x>.result``, ``<x>.reference``), or a name bound
    to one."""
    return (isinstance(target, ast.Attribute) and target.attr == attribute) or (
        isinstance(target, ast.Name) and target.id in aliases)


def _outcome_record(attribute: str) -> type:
    """The record an episode record's ``attribute`` holds: ``result`` an
    :class:`~scenario_bank.records.EpisodeOutcome`, ``reference`` a :class:`~scenario_bank.records.ReferenceOutcome`."""
    from scenario_bank.records import EpisodeOutcome, ReferenceOutcome

    return {"result": EpisodeOutcome, "reference": ReferenceOutcome}[attribute]


def outcome_key_reads(source: str, attribute: str) -> List[str]:
    """The string-key reads of the JSON keys of an episode record's ``attribute`` (``result`` or ``reference``,
    :func:`_outcome_record`) in ``source``: of ``<x>.result`` (``record.result["trajectory_hash"]``, ``(record.result
    or {}).get("steps")``) and of a name a function binds to one (``result = record.result or {}`` then
    ``result.get("params")``)."""
    keys, tree, found = _outcome_record(attribute).json_fields(), ast.parse(source), {}
    scopes = [(tree, frozenset())]
    for function in ast.walk(tree):
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            aliases = {t.id for node in ast.walk(function) if isinstance(node, ast.Assign)
                       and _is_held(_unwrapped(node.value), attribute, frozenset())
                       for t in node.targets if isinstance(t, ast.Name)}
            scopes.append((function, frozenset(aliases)))
    for scope, aliases in scopes:
        for node, target, key in _key_reads(scope):
            if key in keys and _is_held(target, attribute, aliases):
                found[(node.lineno, node.col_offset)] = ast.unparse(node)
    return [found[where] for where in sorted(found)]


def result_key_reads(source: str) -> List[str]:
    """:func:`outcome_key_reads` of episode results (:class:`~scenario_bank.records.EpisodeOutcome`)."""
    return outcome_key_reads(source, "result")


def reference_key_reads(source: str) -> List[str]:
    """:func:`outcome_key_reads` of the reference driver's outcomes (:class:`~scenario_bank.records.ReferenceOutcome`)."""
    return outcome_key_reads(source, "reference")


def _product_reads(reads: typing.Callable[[str], List[str]]) -> Dict[str, List[str]]:
    """``{module path: reads}`` of every product module where ``reads`` finds any."""
    found = {}
    for folder in ("dv2s_gym", "policies", "envs", "scenario_bank"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            found_here = reads(path.read_text(encoding="utf-8"))
            if found_here:
                found[path.relative_to(ROOT).as_posix()] = found_here
    return found


def test_the_failure_read_check_sees_a_failure_read_by_key():
    planted = textwrap.dedent("""
        def run(record, failure, source_failure):
            failure["kind"] = "x"
            return (record.failure["kind"], failure.get("with"), (record.behaviour or {}).get("actor"),
                    source_failure["type"], record.failure.kind, record.reference.get("failure"),
                    dict(record.failure or {}).get("step"), settings["type"])
    """)
    assert failure_key_reads(planted) == ["record.failure['kind']", "failure.get('with')",
                                          "(record.behaviour or {}).get('actor')", "source_failure['type']",
                                          "dict(record.failure or {}).get('step')"]


def test_the_product_reads_failures_and_behaviours_by_their_fields():
    """An episode record's failure and behaviour (and the failures the conversion and the loop pass on) are
    records: no product module reads one by a JSON key."""
    found = {}
    for folder in ("dv2s_gym", "policies", "envs", "scenario_bank"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            where = path.relative_to(ROOT).as_posix()
            if where in _FAILURE_READ_ALLOWED:
                continue
            reads = failure_key_reads(path.read_text(encoding="utf-8"))
            if reads:
                found[where] = reads
    assert not found, f"{found} read a failure or a behaviour by key: read the record's fields (failure.kind)"
    assert failure_key_reads((ROOT / "scenario_bank/records.py").read_text(encoding="utf-8")) == [
        "(self.failure or {}).get('type')"]  # Provenance.failure_type, the one allowed


def test_the_result_read_check_sees_a_result_read_by_key():
    planted = textwrap.dedent("""
        def run(record, episode, settings):
            result = record.result or {}
            steps = result.get("steps")
            return (record.result["trajectory_hash"], (episode.result or {}).get("params"), steps,
                    dict(record.result or {}).get("min_ttc"), record.result.trajectory_hash,
                    record.result.get("cluster"), settings["steps"])

        def other(result):
            return result["steps"], result.get("trajectory_hash")
    """)
    assert result_key_reads(planted) == ["result.get('steps')", "record.result['trajectory_hash']",
                                         "(episode.result or {}).get('params')",
                                         "dict(record.result or {}).get('min_ttc')"]


def test_the_product_reads_episode_results_by_their_fields():
    """An episode record's result (and a held-out episode's) is a record: no product module reads one by a JSON
    key."""
    found = _product_reads(result_key_reads)
    assert not found, f"{found} read an episode result by key: read the record's fields (result.trajectory_hash)"


def test_the_reference_read_check_sees_a_reference_read_by_key():
    planted = textwrap.dedent("""
        def run(record, entry, settings):
            reference = record.reference or {}
            policy = reference.get("policy")
            return (record.reference["failure"], (entry.reference or {}).get("trajectory_hash"), policy,
                    dict(record.reference or {}).get("collided"), record.reference.failure,
                    record.reference.get("kept"), settings["failure"], record.result.get("policy"))

        def other(reference):
            return reference["failure"], reference.get("policy")
    """)
    assert reference_key_reads(planted) == ["reference.get('policy')", "record.reference['failure']",
                                            "(entry.reference or {}).get('trajectory_hash')",
                                            "dict(record.reference or {}).get('collided')"]


def test_the_product_reads_the_reference_driver_s_outcome_by_its_fields():
    """An episode record's reference (the reference driver's outcome, and a mining report's failure entry's) is a
    :class:`~scenario_bank.records.ReferenceOutcome`: no product module reads one by a JSON key."""
    found = _product_reads(reference_key_reads)
    assert not found, f"{found} read a reference outcome by key: read the record's fields (reference.failure)"


_RESULT_KEYS = ["scenario", "seed", "scene_seed", "params", "collided", "collisions", "off_road", "success", "min_ttc",
                "mean_speed", "distance", "episode_return", "steps", "trajectory_hash", "error", "extra", "failed"]
"""The keys of an episode result's JSON object, in the order ``EpisodeResult.to_json`` has always written them."""


def test_a_failure_behaviour_and_result_the_miner_writes_read_back_equal(tmp_path):
    """The miner's episode record of a failure (its worker's, written to episodes.jsonl and read back) holds a
    Failure, a Behaviour and an EpisodeOutcome (its result), is equal to what was written, and writes back the same
    bytes, keys in the order the monitors and ``EpisodeResult.to_json`` have always written them."""
    from dv2s_gym.mining.jsonl import JsonlAppender
    from dv2s_gym.mining.miner import read_records
    from dv2s_gym.mining.monitors import MonitorSettings
    from dv2s_gym.mining.tasks import MineTask, run_mine_task
    from scenario_bank.records import Behaviour, EpisodeOutcome, EpisodeRecord, Failure

    record = run_mine_task(MineTask(index=0, policy="keep_lane", scenario="urban_lead_vehicle_stopped", seed=0,
                                    reference="rule", monitor=MonitorSettings(ttc_threshold=1.0, stall_seconds=5.0))
                           .to_json())
    assert record.error is None and isinstance(record.failure, Failure) and isinstance(record.behaviour, Behaviour)
    assert record.failure.type == "collision" and record.failure.kind.startswith("collision")
    assert isinstance(record.result, EpisodeOutcome) and record.result.collided and record.result.failed
    assert (record.result.scenario, record.result.seed) == ("urban_lead_vehicle_stopped", 0)
    assert len(record.result.trajectory_hash) == 64 and record.result.steps > 0 and not record.result.extra
    path = tmp_path / "episodes.jsonl"
    appender = JsonlAppender(path)
    appender.append(record)
    appender.close()
    written = path.read_bytes()
    (read,) = read_records(path)
    assert isinstance(read.failure, Failure) and isinstance(read.behaviour, Behaviour)
    assert read == record and read.failure == record.failure and read.behaviour == record.behaviour
    assert isinstance(read.result, EpisodeOutcome) and read.result == record.result
    assert (read.result.trajectory_hash, read.result.min_ttc, read.result.result_extra) == (
        record.result.trajectory_hash, record.result.min_ttc, record.result.result_extra)
    assert (read.failure.kind, read.failure.with_, read.behaviour.actor) == (
        record.failure.kind, record.failure.with_, record.behaviour.actor)
    assert json.dumps(read.to_dict(), sort_keys=True).encode("utf-8") == written.strip()
    # the JSON objects' keys in the order the monitors and the behaviour have always written them (the file sorts
    # them), as written and as read back
    for episode in (record, read):
        assert list(episode.to_dict()["failure"]) == ["type", "time", "step", "with_kind", "collision_type",
                                                      "min_ttc", "speed", "with", "kind"]
        assert list(episode.to_dict()["behaviour"]) == ["actor", "actor_manoeuvre", "ego_manoeuvre"]
        assert list(episode.to_dict()["result"]) == _RESULT_KEYS
    saved = json.loads(written)
    assert EpisodeRecord.from_dict(saved).to_dict() == saved
    assert EpisodeOutcome.from_dict(saved["result"]) == read.result
    assert json.dumps(read.result.to_dict(), sort_keys=True) == json.dumps(saved["result"], sort_keys=True)


def test_an_episode_result_s_record_reads_what_to_json_writes():
    """``EpisodeResult.to_json`` is the result's JSON form; ``EpisodeResult.to_record`` reads it into the record an
    episode record holds as its ``result``, which writes it back key for key (and ``from_json`` reads it back)."""
    import math

    from policies.evaluation import EpisodeResult
    from scenario_bank.records import EpisodeOutcome, EpisodeRecord

    result = EpisodeResult("s", 3, 77, {"gap": 20.0}, True, ["car1"], False, False, math.inf, 12.5, 40.0, -1.5, 25,
                           "ab" * 32, min_ttc_time=2.4, min_ttc_with="car1")
    outcome = result.to_record()
    assert isinstance(outcome, EpisodeOutcome) and outcome.to_dict() == result.to_json()
    assert list(outcome.to_dict()) == list(result.to_json()) == _RESULT_KEYS
    assert json.dumps(outcome.to_dict()) == json.dumps(result.to_json())
    assert (outcome.collided, outcome.collisions, outcome.min_ttc, outcome.failed, outcome.error) == (
        True, ("car1",), None, True, None)
    assert outcome.result_extra == {"min_ttc_time": 2.4, "min_ttc_with": "car1"} and not outcome.extra
    assert EpisodeResult.from_json(outcome.to_dict()) == result
    record = EpisodeRecord(index=0, scenario="s", seed=3, result=result.to_json())
    assert record.result == outcome and record.min_ttc == math.inf and record.mean_speed == 12.5
    assert EpisodeRecord(index=0, scenario="s", seed=3).min_ttc == math.inf


def test_an_episode_result_keeps_what_its_json_held():
    """A result read from a file may hold some of the fields: absent keys stay absent, nulls stay null, other keys
    travel in ``extra``; a field of the wrong kind is named from the episode record."""
    from scenario_bank.records import EpisodeOutcome, EpisodeRecord, HeldOutEpisode, RecordError, recorded

    partial = {"min_ttc": None, "steps": 25, "trajectory_hash": "ab", "jerk": 9.5}
    read = EpisodeOutcome.from_dict(partial)
    assert read.to_dict() == partial and list(read.to_dict()) == list(partial)
    assert (read.steps, read.trajectory_hash, read.min_ttc, read.scenario, read.extra) == (
        25, "ab", None, None, {"jerk": 9.5})
    assert not recorded(EpisodeOutcome.from_dict({})) and recorded(read)
    episode = {"index": 0, "scenario": "s", "seed": 3, "result": partial}
    assert EpisodeRecord.from_dict(episode).result == read
    assert EpisodeRecord.from_dict(episode).to_dict()["result"] == partial
    held = HeldOutEpisode.from_dict({"role": "before", "scenario": "s", "seed": 3, "result": partial})
    assert held.result == read and held.to_dict()["result"] == partial
    with pytest.raises(RecordError, match="episode record field 'result.steps' must be an integer, not str"):
        EpisodeRecord.from_dict({**episode, "result": {"steps": "25"}})
    with pytest.raises(RecordError, match="held-out episode field 'result' must be a JSON object, not list"):
        HeldOutEpisode.from_dict({"role": "before", "scenario": "s", "seed": 3, "result": [1]})


def test_a_held_out_episode_s_result_reads_back_equal(tmp_path):
    """A held-out episode (its worker's, saved to heldout.jsonl and read back) holds its result as an
    EpisodeOutcome, equal to what was written and written back as the same bytes."""
    from dv2s_gym.loop.heldout import HeldOutStore
    from dv2s_gym.mining.tasks import heldout_task
    from scenario_bank.records import EpisodeOutcome

    episode = heldout_task({"role": "before", "policy": "keep_lane", "scenario": "urban_lead_vehicle_stopped",
                            "seed": 0})
    assert episode.error is None and isinstance(episode.result, EpisodeOutcome)
    assert episode.failed and episode.result.collided and len(episode.result.trajectory_hash) == 64
    assert list(episode.to_dict()["result"]) == _RESULT_KEYS
    store = HeldOutStore(tmp_path / "heldout.jsonl")
    store.append(episode)
    written = store.path.read_bytes()
    read = HeldOutStore(store.path).get("before", "urban_lead_vehicle_stopped", 0)
    assert read == episode and isinstance(read.result, EpisodeOutcome) and read.result == episode.result
    assert json.dumps(read.to_dict(), sort_keys=True).encode("utf-8") == written.strip()


def test_a_failure_and_behaviour_keep_what_their_json_held():
    """Absent keys stay absent, nulls stay null, a plug-in's keys travel in ``extra``; a record built from the
    JSON object reads it into the records."""
    from scenario_bank.records import Behaviour, EpisodeRecord, Failure, HeldOutEpisode, RecordError

    partial = {"type": "collision", "time": 2.0, "with": None, "kind": "collision:rear_end", "jerk": 9.5}
    failure = Failure.from_dict(partial)
    assert failure.to_dict() == partial and list(failure.to_dict()) == ["type", "time", "with", "kind", "jerk"]
    assert failure.kind == "collision:rear_end" and failure.extra == {"jerk": 9.5} and failure.step is None
    assert Failure("collision", 1.0, 5, collision_type="side").kind == "collision:side"
    assert Failure.of(None) is None and Failure.of({}) is None and Failure.of(partial) == failure
    filled = failure.completed_by(Failure("collision", 2.0, 10, "lead", "car", "rear_end", 0.5, 8.0))
    assert (filled.step, filled.with_, filled.speed, filled.extra) == (10, "lead", 8.0, {"jerk": 9.5})
    assert set(filled.to_dict()) == {"type", "time", "step", "with_kind", "collision_type", "min_ttc", "speed",
                                     "with", "kind", "jerk"}
    behaviour = Behaviour.from_dict({"actor": "car", "ego_manoeuvre": None})
    assert behaviour.to_dict() == {"actor": "car", "ego_manoeuvre": None}
    assert behaviour.complete() == Behaviour("car", "unknown", "unknown")
    episode = {"index": 1, "scenario": "s", "seed": 2, "failure": partial, "behaviour": {"actor": "car"}}
    built = EpisodeRecord(index=1, scenario="s", seed=2, failure=partial, behaviour={"actor": "car"})
    assert isinstance(built.failure, Failure) and isinstance(built.behaviour, Behaviour)
    assert EpisodeRecord.from_dict(episode).to_dict() == {**EpisodeRecord.from_dict(episode).to_dict(), **episode}
    held = HeldOutEpisode.from_dict({"role": "before", "scenario": "s", "seed": 1, "failure": partial})
    assert held.failure == failure and held.to_dict()["failure"] == partial
    with pytest.raises(RecordError, match="episode record field 'failure.type' is missing"):
        EpisodeRecord.from_dict({**episode, "failure": {"kind": "collision"}})
    with pytest.raises(RecordError, match="'failure.step' must be an integer"):
        EpisodeRecord.from_dict({**episode, "failure": {"type": "collision", "step": "ten"}})


_PRODUCT = ("dv2s_gym", "policies", "envs", "scenario_bank")
"""The product's packages."""
_READERS = ("from_dict", "from_json", "from_checked", "of")
"""The readers whose job is to read a record's JSON object (or take the record as it is)."""
_METRICS_REASON = ("the paper's metrics (ElementsLike) score the elements as read from a file too: a conversion report's "
                   "detail.simulated and a label file's JSON object, as element_set reads them")
"""Why the description metrics take an element record or its JSON object."""
RECORD_OR_MAPPING_ALLOWED: Dict[str, str] = {
    "dv2s_gym/mining/conversion/failure_video.py:record_failure_video(record_or_trace)":
        "a user's entry point: it also takes a line of episodes.jsonl as read from the file, and names the fields "
        "it lacks",
    "dv2s_gym/mining/conversion/failure_video.py:write_failure_video(record_or_trace)":
        "a user's entry point: it also takes a line of episodes.jsonl as read from the file, and names the fields "
        "it lacks",
    "scenario_bank/entries.py:new_sidecar(provenance)":
        "takes the provenance a Scenic 2 upgrade returns as a JSON object (admission.upgrade_if_asked)",
    "scenario_bank/entries.py:new_provenance(provenance)":
        "takes the provenance a Scenic 2 upgrade returns as a JSON object (admission.upgrade_if_asked)",
    "scenario_bank/entries.py:new_sidecar(elements)":
        "takes the elements of the Sidecar given to Bank.add, which holds them as its caller built it (a Sidecar "
        "does not read its fields when constructed)",
    "scenario_bank/elements.py:element_set(data)":
        "reads the elements the description metrics are given (pipeline.metrics.ElementsLike): a record or its "
        "JSON object",
    "dv2s_gym/pipeline/metrics.py:as_set(elements)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:scs(ground_truth)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:scs(description)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:hallucination_rate(ground_truth)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:hallucination_rate(description)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:semantic_preservation(description)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:semantic_preservation(scenario)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:e2e_sc(video_ground_truth)": _METRICS_REASON,
    "dv2s_gym/pipeline/metrics.py:e2e_sc(simulated)": _METRICS_REASON,
    "dv2s_gym/loop/verdict.py:heldout_worse(tables)":
        "its PairedTable is the statistics' table (dv2s_gym.regress.stats), no record: the check goes by name",
}
"""``"<module path>:<function>(<parameter>)"`` of the public product functions that still take a record or its JSON
object, each with the reason."""


def record_classes(sources: typing.Iterable[str]) -> typing.FrozenSet[str]:
    """The names of the record classes in ``sources``: :class:`~scenario_bank.records.JsonRecord`, every class
    deriving from a record class, and :class:`~scenario_bank.elements.Elements` (a record of its own kind)."""
    bases: Dict[str, List[str]] = {}
    for source in sources:
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.ClassDef):
                bases.setdefault(node.name, []).extend(ast.unparse(b).split("[")[0].split(".")[-1] for b in node.bases)
    records, grown = {"JsonRecord", "Elements"}, True
    while grown:
        found = {name for name, parents in bases.items() if set(parents) & records} - records
        records |= found
        grown = bool(found)
    return frozenset(records)


def _union_members(node: ast.expr) -> List[ast.expr]:
    """The members of a union annotation (``Union[A, B]``, ``Optional[A]``, ``A | B``), or ``[]``."""
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitOr):
        return _union_members(node.left) or [node.left] + (_union_members(node.right) or [node.right])
    if isinstance(node, ast.Subscript) and ast.unparse(node.value).split(".")[-1] == "Union":
        return list(node.slice.elts) if isinstance(node.slice, ast.Tuple) else [node.slice]
    return []


def _type_name(node: ast.expr) -> str:
    """``Name`` of ``Name``, ``"Name"``, ``module.Name`` and ``Name[...]``."""
    text = node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else ast.unparse(node)
    return text.strip("'\"").split("[")[0].split(".")[-1]


def type_aliases(source: str) -> Dict[str, ast.expr]:
    """``{name: annotation}`` of the type aliases bound at the top of a module's ``source``: ``Name = <type>`` (a
    subscripted type such as ``Sequence[Union[...]]``, or a ``|`` union) and ``Name: TypeAlias = <type>``."""
    found: Dict[str, ast.expr] = {}
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            target, value = node.targets[0], node.value
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None \
                and _type_name(node.annotation) == "TypeAlias":
            target, value = node.target, node.value
        else:
            continue
        if isinstance(value, ast.Subscript) or (isinstance(value, ast.BinOp) and isinstance(value.op, ast.BitOr)):
            found[target.id] = value
    return found


def module_aliases(sources: typing.Mapping[str, str]) -> Dict[str, Dict[str, ast.expr]]:
    """``{dotted module: {alias: annotation}}`` (:func:`type_aliases`) of ``{module path: source}``."""
    return {path[:-3].replace("/", ".").removesuffix(".__init__"): type_aliases(source)
            for path, source in sources.items()}


def _aliases_in_scope(tree: ast.Module, own: Dict[str, ast.expr],
                      imported: typing.Mapping[str, Dict[str, ast.expr]]) -> Dict[str, ast.expr]:
    """The aliases a module's annotations can name: its own and those it imports (``from m import Alias [as A]``,
    an alias of a module of ``imported``)."""
    scope = dict(own)
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module in imported:
            for name in node.names:
                if name.name in imported[node.module]:
                    scope[name.asname or name.name] = imported[node.module][name.name]
    return scope


def _resolved(annotation: ast.expr, aliases: typing.Mapping[str, ast.expr], depth: int = 5) -> ast.expr:
    """``annotation`` with each alias of ``aliases`` it names (``Name``, ``"Name"``, ``module.Name``) replaced by
    what the alias stands for, aliases of aliases too (``depth`` levels)."""
    if isinstance(annotation, ast.Constant) and isinstance(annotation.value, str):
        try:
            annotation = ast.parse(annotation.value, mode="eval").body
        except SyntaxError:
            return annotation

    class Resolve(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> ast.expr:
            return aliases[node.id] if node.id in aliases else node

        def visit_Attribute(self, node: ast.Attribute) -> ast.expr:
            return aliases[node.attr] if node.attr in aliases else self.generic_visit(node)

    for _ in range(depth):
        resolved = Resolve().visit(copy.deepcopy(annotation))
        if ast.dump(resolved) == ast.dump(annotation):
            break
        annotation = resolved
    return annotation


def record_or_mapping_parameters(source: str, records: typing.AbstractSet[str],
                                 imported: typing.Mapping[str, Dict[str, ast.expr]] = None) -> List[str]:
    """``"<function>(<parameter>)"`` of the public functions and methods (``__init__`` of a public class too) in
    ``source`` that take a parameter annotated with a union of a record class of ``records`` and a JSON object
    (``Union[Record, Mapping[str, Any]]``, ``Record | dict``, anywhere in the annotation); the readers
    (:data:`_READERS`) excepted. A type alias the annotation names is read as what it stands for: the module's own
    (``Records = Sequence[Union[Record, Mapping[str, Any]]]``) and one it imports from a module of ``imported``
    (:func:`module_aliases`)."""
    tree, found = ast.parse(source), []
    aliases = _aliases_in_scope(tree, type_aliases(source), imported or {})
    functions = [(node.name, node) for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]
    functions += [(f"{cls.name}.{item.name}", item) for cls in tree.body
                  if isinstance(cls, ast.ClassDef) and not cls.name.startswith("_")
                  for item in cls.body if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef))]
    for name, node in functions:
        short = name.split(".")[-1]
        if (short.startswith("_") and short != "__init__") or short in _READERS:
            continue
        arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
        for argument in arguments:
            annotation = _resolved(argument.annotation, aliases) if argument.annotation else None
            unions = [_union_members(part) for part in ast.walk(annotation)] if annotation else []
            if any({_type_name(m) for m in members} & records
                   and {_type_name(m) for m in members} & {"Mapping", "Dict", "dict", "MutableMapping"}
                   for members in unions):
                found.append(f"{name}({argument.arg})")
    return found


def _product_sources() -> Dict[str, str]:
    return {path.relative_to(ROOT).as_posix(): path.read_text(encoding="utf-8")
            for folder in _PRODUCT for path in sorted((ROOT / folder).rglob("*.py"))}


def test_the_union_check_sees_a_record_or_its_json_object_taken():
    planted = textwrap.dedent("""
        from typing import Any, Dict, Mapping, Optional, Sequence, Union

        class Outcome(JsonRecord): ...
        class Finer(Outcome): ...

        def takes(report: Union[Outcome, Mapping[str, Any]], n: int) -> None: ...
        def optional(report: Union[None, "Finer", Dict[str, Any]] = None) -> None: ...
        def nested(*, episodes: Sequence[Union[Finer, Mapping[str, Any]]]) -> None: ...
        def piped(report: Outcome | dict) -> None: ...
        def record_only(report: Outcome, other: Optional[Mapping[str, Any]]) -> None: ...
        def not_a_record(settings: Union[MonitorSettings, Mapping[str, Any]]) -> None: ...
        def _private(report: Union[Outcome, Mapping[str, Any]]) -> None: ...

        class Reader:
            def __init__(self, data: Union[Outcome, Mapping[str, Any]]) -> None: ...
            @classmethod
            def from_dict(cls, data: Union[Outcome, Mapping[str, Any]]) -> "Reader": ...

        Reports = Sequence[Union[Outcome, Mapping[str, Any]]]
        Either: TypeAlias = Finer | dict
        Again = Optional[Reports]
        Records = Sequence[Outcome]

        def aliased(reports: Reports, either: "Either", again: Again, records: Records) -> None: ...
    """)
    records = record_classes([planted])
    assert {"Outcome", "Finer"} <= records and "Reader" not in records
    assert record_or_mapping_parameters(planted, records) == [
        "takes(report)", "optional(report)", "nested(episodes)", "piped(report)", "aliased(reports)",
        "aliased(either)", "aliased(again)", "Reader.__init__(data)"]
    # an alias imported from another module of the product, under its name or another
    importing = textwrap.dedent("""
        from dv2s_gym.loop.kinds import Reports, Records as Typed
        from dv2s_gym.loop import kinds

        def takes(reports: Reports, typed: Typed, dotted: kinds.Reports) -> None: ...
    """)
    imported = module_aliases({"dv2s_gym/loop/kinds.py": planted})
    assert record_or_mapping_parameters(importing, records, imported) == ["takes(reports)", "takes(dotted)"]
    assert record_or_mapping_parameters(importing, records) == []


def test_no_public_product_function_takes_a_record_or_its_json_object():
    """The product's public functions take the records the product passes them, not a record or its JSON object
    (a misspelt key of such an object would be kept in ``extra`` silently); :data:`RECORD_OR_MAPPING_ALLOWED` lists
    the ones whose callers hand them JSON objects, each with the reason."""
    sources = _product_sources()
    records = record_classes(sources.values())
    assert {"JsonRecord", "EpisodeRecord", "RegressReport", "LoopReportBody", "TrainRun", "FailureInteraction",
            "ReferenceOutcome", "Elements"} <= records
    imported = module_aliases(sources)
    found = [f"{path}:{name}" for path, source in sources.items()
             for name in record_or_mapping_parameters(source, records, imported)]
    unlisted = [name for name in found if name not in RECORD_OR_MAPPING_ALLOWED]
    assert not unlisted, (f"{unlisted} take a record or its JSON object: take the record (the callers read a JSON "
                          "object with the record's from_dict), or list it in RECORD_OR_MAPPING_ALLOWED with the reason")
    stale = sorted(set(RECORD_OR_MAPPING_ALLOWED) - set(found))
    assert not stale, f"{stale} no longer take a record or its JSON object: remove them from RECORD_OR_MAPPING_ALLOWED"


_ROW_READERS = ("read_rows",)
"""The readers of a JSON-lines file's rows as JSON objects (:func:`dv2s_gym.mining.jsonl.read_rows`)."""


def _reads_rows(node: ast.AST, rows: typing.AbstractSet[str]) -> bool:
    """Whether ``node`` holds rows as read: a call of a row reader (:data:`_ROW_READERS`) or a name bound to them."""
    return any((isinstance(part, ast.Call) and ast.unparse(part.func).split(".")[-1] in _ROW_READERS)
               or (isinstance(part, ast.Name) and part.id in rows) for part in ast.walk(node))


def _bound_names(target: ast.expr) -> typing.Set[str]:
    return {node.id for node in ast.walk(target) if isinstance(node, ast.Name)}


def row_key_reads(source: str) -> List[str]:
    """The string-key reads (``row["cluster"]``, ``row.get("status")``) of a row a JSON-lines reader returned
    (:data:`_ROW_READERS`) in ``source``: of the call itself, of a name bound to its rows (``rows = read_rows(p)``),
    and of a loop's or a comprehension's name over them (``for row in read_rows(p) + read_rows(q)``, ``{r["cluster"]
    for r in read_rows(p)}``)."""
    tree, found = ast.parse(source), {}
    functions = (ast.FunctionDef, ast.AsyncFunctionDef)
    top = ast.Module(body=[node for node in tree.body if not isinstance(node, functions + (ast.ClassDef,))],
                     type_ignores=[])
    for scope in [top] + [node for node in ast.walk(tree) if isinstance(node, functions)]:
        rows: typing.Set[str] = set()
        for _ in range(3):  # a name bound to rows, then a loop over that name...
            for node in ast.walk(scope):
                if isinstance(node, ast.Assign) and _reads_rows(node.value, rows):
                    rows |= set().union(*(_bound_names(t) for t in node.targets))
                elif isinstance(node, (ast.For, ast.AsyncFor, ast.comprehension)) and _reads_rows(node.iter, rows):
                    rows |= _bound_names(node.target)
        for node, target, _ in _key_reads(scope):
            if _reads_rows(target, rows):
                found[(node.lineno, node.col_offset)] = ast.unparse(node)
    return [found[where] for where in sorted(found)]


def test_the_row_read_check_sees_a_json_lines_row_read_by_key():
    planted = textwrap.dedent("""
        def run(path, settings):
            rows = read_rows(path)
            first = rows[0]["cluster"]
            for row in read_rows(path / "conversions.jsonl") + read_rows(path / "replays.jsonl"):
                status = row.get("status", "?")
            kept = {r["replay_entry"] for r in jsonl.read_rows(path) if r.get("replay_entry")}
            for number, line in enumerate(rows, 1):
                cluster = line["cluster"]
            records = [ConversionRecord.from_dict(row) for row in read_rows(path)]
            return read_rows(path)[0]["index"], records[0].cluster, settings["cluster"], kept

        def other(records):
            return [(record.reproduction or {}).get("rate") for record in records]
    """)
    assert row_key_reads(planted) == ["rows[0]['cluster']", "row.get('status', '?')", "r['replay_entry']",
                                      "r.get('replay_entry')", "line['cluster']", "read_rows(path)[0]['index']"]


def test_the_product_reads_json_lines_rows_through_their_records():
    """A row of a mining run's JSON-lines files (``episodes.jsonl``, ``conversions.jsonl``, ``replays.jsonl``,
    ``heldout.jsonl``) is read into its record (``read_records``, ``read_conversions``, ``read_replays``, a record's
    ``from_dict``), never by a literal key: a misspelt key would be a silent ``None``, a silent 0 in a count."""
    found = {path: reads for path, reads in _product_reads(row_key_reads).items() if path != "dv2s_gym/mining/jsonl.py"}
    assert not found, f"{found} read a JSON-lines row by key: read it into its record and read the record's fields"


def test_a_conversion_s_report_and_an_exact_replay_s_row_are_typed_records(tmp_path):
    """A conversion's report.json (the record's fields with each stage's details, its ``description`` the generated
    description's object) reads into a ConversionOutcome, and writes back the same JSON object; a replays.jsonl row
    into a ReplayRow, which writes back the line the replay's dict wrote."""
    from dv2s_gym.mining.conversion.record import (ConversionOutcome, ConversionStatus, ReplayRow, read_conversion_outcome,
                                                   read_replays)
    from dv2s_gym.mining.jsonl import JsonlAppender
    from scenario_bank.records import RecordError

    report = {**_CONVERSION, "rejections": ["judge: no"], "description": {"text": "A car brakes.", "elements": {}},
              "reproduction": {"rate": 0.5, "clip": {"seed": 3, "failed": False}}, "check": {"ran": True}}
    path = tmp_path / "report.json"
    path.write_text(json.dumps(report, indent=2) + "\n")
    outcome = read_conversion_outcome(path)
    assert isinstance(outcome, ConversionOutcome) and outcome.merged and outcome.status is ConversionStatus.MERGED
    assert outcome.rejections == ("judge: no",) and outcome.reproduction["clip"]["seed"] == 3 and outcome.policy is None
    assert outcome.to_dict() == report
    path.write_text(json.dumps({**report, "rejections": "judge: no"}))
    with pytest.raises(RecordError, match=r"report.json: conversion report field 'rejections'"):
        read_conversion_outcome(path)
    row = {"cluster": "c", "index": 3, "scenario": "s", "status": "rejected", "replay_entry": None,
           "reason": "replay: no", "note": None, "seconds": 1.25}
    replays = tmp_path / "replays.jsonl"
    appender = JsonlAppender(replays)
    appender.append(ReplayRow(cluster="c", index=3, scenario="s", status=ConversionStatus.REJECTED, reason="replay: no",
                              seconds=1.25))
    appender.close()
    assert replays.read_text() == json.dumps(row, sort_keys=True) + "\n"  # the line the dict wrote
    (read,) = read_replays(replays)
    assert read.to_dict() == row and not read.kept and read.status is ConversionStatus.REJECTED
