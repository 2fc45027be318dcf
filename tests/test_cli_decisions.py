"""The command line parses and prints; the decisions are the product modules': what a conversion's report means,
which story check failed, a resumed run's settings, which kind of file replay was given, the lists of choices."""

import argparse
import json
import re
from pathlib import Path

import pytest

from dv2s_gym.cli import build_parser
from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import env_config_option, json_option, json_value
from dv2s_gym.loop.settings import FINE_TUNE_METHODS
from dv2s_gym.cli.convert import report_text
from dv2s_gym.pipeline.convert import (UNPLACED_WARNING, ConversionReport, ScenarioCheck, checks_passed, generated,
                                       placed_nothing)
from dv2s_gym.pipeline.stages import Description, Generation
from dv2s_gym.pipeline.prompts import CAMERA_VIEWPOINTS
from dv2s_gym.story import UnknownEgoError, check_stories
from envs.trace import saved_file_schema
from scenario_bank.elements import Elements
from scenario_bank.errors import UnknownScenarioError

CLI = Path(build_parser.__code__.co_filename).parent


def _choices(argv, option):
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices[argv[0]]
    for name in argv[1:]:
        sub = sub._subparsers._group_actions[0].choices[name]
    return next(a.choices for a in sub._actions if option in a.option_strings)


def _conversion(elements, warnings=(), ok=True, sp=0.5):
    return ConversionReport(
        description=Description("a text", Elements.from_dict(elements), backend="user"),
        generation=Generation("script", "rules", warnings=list(warnings),
                              intended_elements=Elements(participants=("ego",))),
        check=ScenarioCheck(safe=True, compiled=True, sampled=True, ran=ok), sp=sp, files=["report.json"])


def test_a_generation_report_decides_its_own_outcome():
    nothing = _conversion({"road": None, "participants": [], "actions": [], "relations": []})
    assert placed_nothing(nothing) and checks_passed(nothing) and not generated(nothing)
    placed = _conversion({"road": "highway"})
    assert generated(placed) and not generated(_conversion({"road": "highway"}, ok=False))
    failed = ConversionReport(description=placed.description, generation_error="ValueError: no", files=["report.json"])
    assert not placed_nothing(failed) and not checks_passed(failed) and not generated(failed)
    assert not hasattr(__import__("dv2s_gym.cli.convert", fromlist=["x"]), "placed_nothing")


def test_whether_the_sp_scores_only_the_placed_parts_is_the_reports_own():
    partly = _conversion({"road": "highway"}, warnings=[f"{UNPLACED_WARNING}: 'while the sun sets'"])
    assert partly.partial_sp and not _conversion({"road": "highway"}, warnings=["not shown: x"]).partial_sp
    assert not _conversion({"road": "highway"}, warnings=[f"{UNPLACED_WARNING}: 'x'"], sp=None).partial_sp
    text = report_text(partly, "out")
    assert "\nSP: 0.50 (of the parts of the description that were placed)\n" in text
    assert "warning: could not place: 'while the sun sets'" in text and "checks: safe=ok" in text
    assert "SP: 0.50\n" in report_text(_conversion({"road": "highway"}), "out")


def test_a_story_check_names_an_unknown_scenario_or_ego_as_a_project_error():
    with pytest.raises(UnknownScenarioError, match="unknown scenario 'nosuch' in the bank"):
        check_stories(["nosuch"], ["idm"], seeds=1)
    with pytest.raises(UnknownEgoError, match="unknown ego 'nosuch'; choose from scenic"):
        check_stories(["highway_lead_vehicle_stopped"], ["nosuch"], seeds=1)
    text = (CLI / "bank_validate.py").read_text()
    assert "check_stories(" in text and "story_table(" not in text and "ALL_EGOS" not in text


def test_a_resumed_run_keeps_its_recorded_settings_unless_told_otherwise(tmp_path):
    pytest.importorskip("torch")  # the rl extra
    from policies import training
    recorded = training.TrainConfig.from_json({"out": str(tmp_path), "steps": 5000, "seed": 3, "n_envs": 1})
    (tmp_path / "run.json").write_text(json.dumps({"schema": "dv2s-train-run", "version": 2,
                                                   "config": recorded.to_json()}))
    resumed = training.run_settings(str(tmp_path), {"steps": 9000, "seed": None}, resume=True)
    assert (resumed.steps, resumed.seed, resumed.n_envs) == (9000, 3, 1)
    fresh = training.run_settings(str(tmp_path), {"steps": 9000}, resume=False)
    assert fresh.seed != 3 or fresh.n_envs != 1
    assert "load_run_config" not in (CLI / "train.py").read_text()


def test_replay_asks_the_trace_module_which_kind_of_file_it_was_given(tmp_path):
    (tmp_path / "r.json").write_text(json.dumps({"schema": "dv2s-regress-report"}))
    (tmp_path / "t.json").write_text(json.dumps({"scenario": "x"}))
    (tmp_path / "z.gz").write_bytes(b"\x1f\x8b rest")
    assert saved_file_schema(tmp_path / "r.json") == "dv2s-regress-report"
    assert saved_file_schema(tmp_path / "t.json") is None and saved_file_schema(tmp_path / "z.gz") is None
    assert saved_file_schema(tmp_path / "missing.json") is None
    assert "json.loads" not in (CLI / "replay.py").read_text()


def test_choices_come_from_the_product_lists():
    assert sorted(_choices(["convert"], "--camera")) == sorted(CAMERA_VIEWPOINTS)
    assert tuple(_choices(["loop"], "--fine-tune-method")) == FINE_TUNE_METHODS


def test_one_parser_reads_every_config_option(tmp_path):
    assert env_config_option('{"duration": 3}') == {"duration": 3}
    (tmp_path / "c.json").write_text('{"duration": 4}')
    assert env_config_option(str(tmp_path / "c.json")) == {"duration": 4}
    for bad in ("{duration: 3", "[1]", str(tmp_path / "none.json")):
        with pytest.raises(UsageError, match="--config"):
            env_config_option(bad)
    for module in ("mine.py", "regress.py", "train.py"):
        text = (CLI / module).read_text()
        assert "env_config_option(args.config)" in text and 'json_option(args.config' not in text, module


def test_json_options_have_one_parser_and_one_error_shape(tmp_path):
    """Every JSON value the command line takes is parsed by inputs.json_value (inline, or a .json file through
    json_option), size and depth capped, and every error reads ``{what} must be {wanted}, e.g. {example}; {why}``."""
    import ast

    parsers = [f"{path.name}:{node.lineno}" for path in sorted(CLI.glob("*.py"))
               for node in ast.walk(ast.parse(path.read_text()))
               if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
               and node.func.attr in ("loads", "load", "load_json_bounded") and path.name != "inputs.py"]
    assert not parsers, f"JSON parsed outside dv2s_gym/cli/inputs.py: {parsers}"
    (tmp_path / "w.json").write_text('{"a": 2}')
    assert json_option(str(tmp_path / "w.json"), "--w", "an object") == {"a": 2}
    assert json_value('[1, 2]', "--w", "a value") == [1, 2] and json_option(None, "--w", "an object") is None
    shape = r"^--w must be a JSON object of weights, e\.g\. '\{\"a\": 1\}'; "
    for bad, why in (("{a: 1", "it is not valid JSON \\(Expecting property name"), ("[1]", "it is a JSON array"),
                     ("[" * 200 + "]" * 200, "it nests arrays and objects deeper than"),
                     (" " * (1 << 21), "it is larger than"), (str(tmp_path / "none.json"), "there is no file")):
        with pytest.raises(UsageError, match=shape + why):
            json_option(bad, "--w", "a JSON object of weights", "'{\"a\": 1}'", mapping=True)
    with pytest.raises(UsageError, match=r"^the elements file x must be JSON; it is not UTF-8 text"):
        json_value(b"\xff", "the elements file x", "JSON")


@pytest.mark.parametrize("argv, flag", [
    (["bank", "sample", "--weights", "{a"], "--weights"),
    (["bank", "sample", "--weights", '{"a": "x"}'], "--weights"),
    (["loop", "--fine-tune-reward", "[1]"], "--fine-tune-reward"),
    (["regress", "--policy", "idm", "--config", "{x"], "--config"),
])
def test_every_json_option_reports_in_the_one_shape(tmp_path, capsys, argv, flag):
    from cli_helpers import run

    code, _, err = run(capsys, *argv[:1], *(["--out", tmp_path / "out"] if argv[0] == "loop" else []), *argv[1:])
    assert code == 2 and re.search(rf"dv2s: error: {flag} must be .*, e\.g\. '.*'; ", err), err


def test_bank_add_upgrades_scenic2_once():
    assert "upgrade_scenic2(" not in (CLI / "bank.py").read_text()
