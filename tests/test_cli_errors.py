"""The `dv2s` command's error contract: one clear line on stderr and a non-zero exit for every
error the project raises (``--debug`` adds the traceback); ``--bank`` anywhere; a folder that is
not a bank refused; file lists that name only what was written."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from llm_server import closed_port_url

from cli_helpers import one_line_error, run
from scenario_bank.bank import BANK_DIR

EVALSET = Path(__file__).resolve().parents[1] / "dv2s_gym" / "evalset"
VIDEO = sorted(EVALSET.glob("*.webm"))[0]


@pytest.fixture
def no_llm_env(monkeypatch):
    for name in ("OPENAI_API_KEY", "DV2S_LLM_API_KEY", "DV2S_VLM_API_KEY", "DV2S_LLM_BASE_URL",
                 "DV2S_VLM_BASE_URL", "DV2S_LLM_MODEL", "DV2S_VLM_MODEL"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("DV2S_LLM_RETRIES", "0")


def test_describe_openai_without_api_key_is_one_line(capsys, no_llm_env):
    code, out, err = run(capsys, "describe", VIDEO, "--dra", "openai")
    line = one_line_error(err)
    assert code == 2 and out == ""
    assert "needs an API key" in line and "OPENAI_API_KEY" in line


def test_describe_openai_unreachable_endpoint_is_one_line(capsys, no_llm_env):
    url = closed_port_url()
    code, out, err = run(capsys, "describe", VIDEO, "--dra", "openai", "--base-url", url)
    line = one_line_error(err)
    assert code == 2 and "could not connect" in line and url in line


def test_debug_shows_the_traceback(capsys, no_llm_env):
    code, _, err = run(capsys, "--debug", "describe", VIDEO, "--dra", "openai")
    assert code == 2
    assert "Traceback (most recent call last)" in err and "MissingAPIKeyError" in err
    assert err.strip().splitlines()[-1].startswith("dv2s: error: ")


def test_missing_video_and_bad_trace_are_one_line(capsys, tmp_path):
    code, _, err = run(capsys, "describe", tmp_path / "nope.webm")
    assert code == 2 and "nope.webm" in one_line_error(err)
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    code, _, err = run(capsys, "replay", bad)
    assert code == 2 and "not a dv2s episode trace" in one_line_error(err)


@pytest.mark.slow
def test_failed_generate_lists_only_what_it_wrote(capsys, tmp_path, no_llm_env):
    out_dir = tmp_path / "gen"
    out_dir.mkdir()
    (out_dir / "scenario.scenic").write_text("# an earlier run's result\n")
    code, out, err = run(capsys, "generate", "The lead car brakes hard.", "--sg", "openai",
                         "--base-url", closed_port_url(), "--out", out_dir)
    assert code == 1
    assert "generation failed" in out and "could not connect" in out
    written = sorted(p.name for p in out_dir.iterdir())
    assert written == ["description.txt", "elements.json", "report.json"]
    assert f"written to {out_dir}/ (description.txt, elements.json, report.json)" in out
    assert json.loads((out_dir / "report.json").read_text())["files"] == written


@pytest.fixture
def small_bank(tmp_path):
    root = tmp_path / "bank"
    root.mkdir()
    for name in ("highway_lead_vehicle_brakes", "urban_pedestrian_crossing"):
        shutil.copytree(BANK_DIR / name, root / name)
    return root


@pytest.mark.parametrize("order", ["before", "between", "after"])
def test_bank_option_before_or_after_the_subcommand(capsys, small_bank, order):
    argv = {"before": ["--bank", small_bank, "bank", "list"],
            "between": ["bank", "--bank", small_bank, "list"],
            "after": ["bank", "list", "--bank", small_bank]}[order]
    code, out, err = run(capsys, *argv, "--json")
    assert code == 0, err
    names = [s["name"] for s in json.loads(out)["scenarios"]]
    assert names == ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]


def test_convert_takes_bank_before_the_subcommand_too():
    from dv2s_gym.cli import build_parser

    args = build_parser().parse_args(["--bank", "B", "convert", "v.webm", "--add-to-bank"])
    assert args.bank == "B"
    args = build_parser().parse_args(["convert", "v.webm", "--add-to-bank", "--bank", "C"])
    assert args.bank == "C"


def test_convert_refuses_a_bank_it_would_not_add_to(tmp_path, capsys):
    video = tmp_path / "v.webm"
    video.write_bytes(b"not read: the options are refused first")
    code, _, err = run(capsys, "convert", video, "--bank", tmp_path / "bank", "--out", tmp_path / "out")
    assert code == 2 and err.count("\n") == 1
    assert "nothing is added without --add-to-bank, so it would be ignored: add --add-to-bank, or drop --bank" in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "bank").exists()


def _command(name, reads_bank):
    """A command group as docs/cli.md describes one: ``dv2s NAME`` prints the names of the bank it reads, which it
    declares (``bank_option``) and opens with ``open_bank`` when ``reads_bank``, else opens with ``Bank()``."""
    from types import SimpleNamespace

    from dv2s_gym.cli.inputs import open_bank
    from dv2s_gym.cli.parser import bank_option
    from scenario_bank.bank import Bank

    def add_parser(subparsers):
        p = subparsers.add_parser(name, help="the bank's names")
        if reads_bank:
            bank_option(p)
        p.set_defaults(func=run)

    def run(args):
        print(" ".join(sorted(entry.name for entry in (open_bank(args) if reads_bank else Bank()))))
        return 0

    return SimpleNamespace(add_parser=add_parser, run=run)


def test_bank_before_a_command_that_reads_none_is_refused(capsys, monkeypatch, small_bank):
    import dv2s_gym.cli as cli

    monkeypatch.setattr(cli, "COMMAND_GROUPS", cli.COMMAND_GROUPS + (_command("mycmd", reads_bank=False),))
    for argv in (["--bank", "/nonexistent", "mycmd"], ["--bank", small_bank, "mycmd"],
                 ["--bank", small_bank, "demo"], ["--bank", small_bank, "replay", "t.json"]):
        code, out, err = run(capsys, *argv)
        line = one_line_error(err)
        assert code == 2 and out == "", argv
        assert f"`dv2s {argv[2]}` reads none" in line and "drop --bank" in line and str(argv[1]) in line, line
        assert "run, bank, convert, regress, mine, train, loop" in line, line
    code, out, _ = run(capsys, "mycmd")
    assert code == 0 and "highway_lead_vehicle_brakes" in out.split()


def test_bank_before_a_command_that_reads_one_reaches_it(capsys, monkeypatch, small_bank):
    import dv2s_gym.cli as cli

    monkeypatch.setattr(cli, "COMMAND_GROUPS", cli.COMMAND_GROUPS + (_command("mycmd", reads_bank=True),))
    for argv in (["--bank", small_bank, "mycmd"], ["mycmd", "--bank", small_bank]):
        code, out, err = run(capsys, *argv)
        assert code == 0 and out.split() == ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"], err
    code, _, err = run(capsys, "--bank", "/nonexistent", "mycmd")
    assert code == 2 and "there is no bank at /nonexistent" in one_line_error(err)
    code, out, _ = run(capsys, "mycmd")
    assert code == 0 and len(out.split()) > 2  # without --bank: the shipped bank


def test_a_folder_that_is_not_a_bank_is_refused(capsys, tmp_path):
    folder = tmp_path / "photos"
    (folder / "2024").mkdir(parents=True)
    (folder / "2025").mkdir()
    (folder / "notes.txt").write_text("x")
    for argv in (["bank", "list", "--bank", folder], ["bank", "stats", "--bank", folder],
                 ["bank", "add", tmp_path / "x.scenic", "--description", "d", "--bank", folder]):
        (tmp_path / "x.scenic").write_text("param map = 'highway_straight'\n")
        code, out, err = run(capsys, *argv)
        line = one_line_error(err)
        assert code == 2 and "is not a scenario bank" in line and str(folder) in line, argv
        assert "2024" not in out and "broken" not in out


def test_what_marks_a_bank(tmp_path, small_bank):
    from scenario_bank.bank import Bank, NotABankError

    assert len(Bank(tmp_path / "new")) == 0  # a folder that does not exist yet: a new bank
    (tmp_path / "empty").mkdir()
    assert len(Bank(tmp_path / "empty")) == 0  # an empty folder: a new bank
    broken = small_bank / "half_written"
    broken.mkdir()
    (broken / "scenario.scenic").write_text("x")  # an entry without its sidecar still marks a bank
    bank = Bank(small_bank)
    assert len(bank) == 2 and "half_written" in bank.problems
    (tmp_path / "other" / "sub").mkdir(parents=True)
    with pytest.raises(NotABankError, match="not a scenario bank"):
        Bank(tmp_path / "other")
    (tmp_path / "afile.txt").write_text("x")
    with pytest.raises(NotABankError, match="not a scenario bank: it is a file"):
        Bank(tmp_path / "afile.txt")


@pytest.mark.parametrize("command", [["bank", "list"], ["bank", "stats"], ["run", "highway_lead_vehicle_brakes"]])
def test_a_bank_that_is_a_file_is_refused_by_every_command_alike(capsys, tmp_path, command):
    (tmp_path / "afile.txt").write_text("x")
    code, _, err = run(capsys, *command, "--bank", tmp_path / "afile.txt")
    assert code == 2 and "is not a scenario bank: it is a file" in one_line_error(err)


def test_a_bank_that_does_not_exist_is_refused_for_reading(capsys, tmp_path):
    code, _, err = run(capsys, "bank", "list", "--bank", tmp_path / "typo")
    assert code == 2 and "there is no bank at" in one_line_error(err)


def test_validating_a_bank_that_does_not_exist_fails(capsys, tmp_path):
    # it used to print "0/0 scenarios valid" and exit 0, passing a typo'd path in CI
    code, out, err = run(capsys, "bank", "validate", "--bank", tmp_path / "typo")
    assert code == 2 and "there is no bank at" in one_line_error(err) and "valid" not in out
    assert not (tmp_path / "typo").exists()


@pytest.mark.parametrize("argv, named, hint", [
    (["regress", "--polcy", "rule"], "unrecognized arguments: --polcy; did you mean --policy?", "dv2s regress --help"),
    (["bank", "validate", "--storyy"], "unrecognized arguments: --storyy; did you mean --story?",
     "dv2s bank validate --help"),
    (["mine"], "the following arguments are required: --policy", "dv2s mine --help"),
    (["run", "x", "--frobnicate"], "unrecognized arguments: --frobnicate", "dv2s run --help"),
])
def test_usage_errors_are_one_line_from_the_subcommand(capsys, argv, named, hint):
    """A wrong or missing option is named by the subcommand it was given to, in one line with where
    its help is, not after argparse's whole usage block."""
    with pytest.raises(SystemExit) as stop:
        from dv2s_gym.cli import main

        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert err.count("\n") == 1 and "usage:" not in err
    assert named in err and hint in err and err.startswith(f"dv2s {argv[0]}")


@pytest.mark.parametrize("argv, named", [
    (["describe", "x.webm", "--sg", "rules"],
     "unrecognized arguments: --sg; `--sg` is an option of `dv2s generate`, `dv2s convert`, `dv2s mine`, `dv2s eval`, "
     "not of `dv2s describe` (see `dv2s describe --help`)"),
    (["regress", "--policy", "rule", "--budget", "5"],
     "unrecognized arguments: --budget; `--budget` is an option of `dv2s mine`, `dv2s loop`, not of `dv2s regress`"),
    (["run", "x", "--debug"], "`--debug` is an option of `dv2s` (before the command), not of `dv2s run`"),
    (["regress", "--policy", "rule", "--frobnicate"], "unrecognized arguments: --frobnicate (see"),
])
def test_an_option_of_another_subcommand_is_named_as_theirs_not_given_a_far_fetched_suggestion(capsys, argv, named):
    with pytest.raises(SystemExit) as stop:
        from dv2s_gym.cli import main

        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1
    assert named in err and "did you mean" not in err, err


STUCK_COMPILING = """param map = 'highway_straight'
model scenic.domains.driving.model
ego = new Car
k = 0
while True:
    k = k + 1
"""


@pytest.mark.slow
def test_a_script_stuck_compiling_stops_at_the_compile_limit_as_an_expected_outcome(capsys, tmp_path, monkeypatch):
    import time

    from scenario_bank.jail import jail_status

    if not jail_status()[0]:
        pytest.skip(f"no jail here: {jail_status()[1]}")
    script = tmp_path / "stuck.scenic"
    script.write_text(STUCK_COMPILING)
    monkeypatch.setenv("DV2S_JAIL_COMPILE_SECONDS", "4")
    started = time.monotonic()
    code, _, err = run(capsys, "run", script, "--duration", "1", "--video", tmp_path / "episode.webm")
    assert time.monotonic() - started < 60
    line = one_line_error(err)
    assert code == 2 and "4 s wall-clock limit while compiling" in line, line
    assert "unexpected error" not in line and "--debug" not in line


@pytest.mark.slow
def test_run_takes_its_scenario_from_the_bank_given(capsys, tmp_path):
    bank = tmp_path / "bank"
    bank.mkdir()
    shutil.copytree(BANK_DIR / "highway_lead_vehicle_brakes", bank / "only_in_this_bank")
    code, out, err = run(capsys, "--bank", bank, "run", "only_in_this_bank", "--duration", "1",
                         "--video", tmp_path / "episode.webm", "--json")
    assert code == 0, err
    assert json.loads(out)["scenario"] == "only_in_this_bank"


@pytest.mark.parametrize("name, content", [("notes.mp4", b"hello\n"), ("cut.webm", bytes(range(256)) * 20)])
def test_a_file_that_is_not_a_video_gives_one_line_and_no_ffmpeg_noise(tmp_path, name, content):
    # a fresh process: FFmpeg prints its own lines ("moov atom not found") to the stderr file descriptor,
    # which only a separate process sees
    video = tmp_path / name
    video.write_bytes(content)
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    done = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "describe", str(video)], capture_output=True,
                          text=True, env=env, timeout=300)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("dv2s: error: cannot read video") and "ffmpeg -i" in lines[0]


def test_a_reader_that_goes_away_stops_the_command_quietly(monkeypatch, capsys):
    """`dv2s bank list | head -1`: the closed pipe ends the command without an error line."""
    import dv2s_gym.cli as cli
    import dv2s_gym.cli.bank as bank_commands

    def closed_pipe(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(bank_commands, "run_list", closed_pipe)
    monkeypatch.setattr(cli, "_silence_stdout", lambda: None)  # the test's own stdout stays usable
    assert cli.main(["bank", "list"]) == 141
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_run_prints_a_summary_for_people_and_json_on_request(capsys, tmp_path):
    video = tmp_path / "episode.webm"
    code, out, err = run(capsys, "run", "highway_lead_vehicle_brakes", "--duration", "1", "--video", video,
                         "--trace", tmp_path / "t.json.gz")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0] == f"wrote {video} (6 frames)"
    assert lines[1].startswith("highway_lead_vehicle_brakes, seed 0 (scene seed ") and "5 steps" in lines[1]
    assert "), driven by the rule-based driver: 5 steps" in lines[1]
    assert lines[2].startswith("outcome: no collision, on the road") and any(l.startswith("scene: ") for l in lines)
    assert lines[-1] == f"trace: {tmp_path / 't.json.gz'}" and "{" not in out
    code, out, _ = run(capsys, "run", "highway_lead_vehicle_brakes", "--duration", "1", "--video", video, "--json")
    result = strict_json(out)
    assert code == 0 and result["steps"] == 5 and result["driver"] == "rule-based"
    assert result["min_ttc"] is None or isinstance(result["min_ttc"], float)


def strict_json(text: str):
    """``text`` parsed as strict JSON: ``Infinity``, ``-Infinity`` and ``NaN`` are refused."""
    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_json_text_is_strict_json_with_non_finite_numbers_as_null():
    import numpy as np

    from dv2s_gym.cli.output import json_text

    data = {"min_ttc": float("inf"), "nested": [{"x": float("nan")}, (1, -float("inf"))], "f32": np.float32("inf"),
            "ok": 2.5, "n": 3, "flag": True, "path": Path("a/b")}
    assert strict_json(json_text(data)) == {"min_ttc": None, "nested": [{"x": None}, [1, None]], "f32": None,
                                            "ok": 2.5, "n": 3, "flag": True, "path": "a/b"}


def test_every_json_output_of_the_cli_goes_through_the_strict_helper():
    """`print(json.dumps(...))` would let Infinity and NaN through; the CLI prints JSON with json_text only."""
    import re

    package = Path(__file__).resolve().parents[1] / "dv2s_gym" / "cli"
    offenders = [f"{path.name}:{number}" for path in sorted(package.glob("*.py")) if path.name != "output.py"
                 for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                 if re.search(r"print\(json\.dumps", line)]
    assert offenders == []


def test_runs_seed_option_says_what_it_does():
    run_help = next(a.help for a in _run_parser()._actions if "--seed" in a.option_strings)
    assert run_help and "same seed gives the same episode" in run_help


def _run_parser():
    import argparse

    from dv2s_gym.cli import run as run_command
    from dv2s_gym.cli.parser import Parser

    sub = Parser(prog="dv2s").add_subparsers()
    run_command.add_parser(sub)
    return sub.choices["run"]


@pytest.mark.slow
def test_a_seeded_random_run_is_the_same_every_time(capsys, tmp_path):
    """`dv2s run --random --seed 5` twice: the same random actions, so the same episode."""
    results = []
    for k in range(2):
        code, out, err = run(capsys, "run", "highway_lead_vehicle_brakes", "--random", "--seed", "5", "--duration", "2",
                             "--video", tmp_path / f"episode{k}.webm", "--json")
        assert code == 0, err
        result = json.loads(out)
        results.append({key: value for key, value in result.items() if key != "path"})
    assert results[0]["steps"] == 10 and results[0]["driver"] == "random"
    assert results[0] == results[1]


@pytest.mark.parametrize("argv, command", [
    (["bank", "show", "nosuch"], "`dv2s bank show`"),
    (["bank", "rm", "nosuch"], "`dv2s bank rm`"),
    (["demo", "--scenario", "nosuch"], "`dv2s demo --scenario`"),
])
def test_commands_taking_a_bank_name_advise_a_bank_name(argv, command, capsys, tmp_path):
    if argv[1] == "rm":
        argv = ["--bank", str(tmp_path)] + argv
    elif argv[0] == "demo":
        argv = argv + ["--out", str(tmp_path / "demo")]
    code, _, err = run(capsys, *argv)
    line = one_line_error(err)
    assert code == 2 and f"{command} takes the name of a scenario in the" in line and "'nosuch'" in line
    assert ".scenic file" not in line and "tag:" not in line
    assert not (tmp_path / "demo").exists() or not list((tmp_path / "demo").iterdir())


def test_bank_show_suggests_the_bank_name_meant(capsys):
    code, _, err = run(capsys, "bank", "show", "highway_lead_vehicle_brake")
    assert code == 2 and "Did you mean 'highway_lead_vehicle_brakes'" in one_line_error(err)
