"""Bad input reaches the user as a project error (a DV2SError that is also the built-in it replaces); a ValueError
that is not one is a fault, and the command line says so instead of passing it off as the user's mistake."""

import json

import pytest

from dv2s_gym import cli
from dv2s_gym.cli import bank as cli_bank
from dv2s_gym.pipeline.errors import EmptyDescriptionError, LLMConfigError
from dv2s_gym.pipeline.llm_client import ChatClient
from dv2s_gym.pipeline.sg.rules import generate_rules
from envs.trace import EpisodeTrace, TraceFileError
from scenario_bank.errors import DV2SError, MissingFileError, SettingError, WrongFileError
from scenario_bank.maps import resolve_map


def _command(raised, monkeypatch, capsys):
    def run(args):
        raise raised
    monkeypatch.setattr(cli_bank, "run_list", run)  # `dv2s bank list` raises it
    code = cli.main(["bank", "list"])
    return code, capsys.readouterr().err


def test_a_value_error_from_a_bug_is_not_passed_off_as_bad_input(monkeypatch, capsys):
    code, err = _command(ValueError("too many values to unpack (expected 2)"), monkeypatch, capsys)
    assert code == 2 and "an unexpected error: rerun with --debug" in err


def test_a_project_error_and_an_os_error_read_as_one_clean_line(monkeypatch, capsys):
    code, err = _command(SettingError("--x must be positive; pass e.g. 3"), monkeypatch, capsys)
    assert (code, err) == (2, "dv2s: error: --x must be positive; pass e.g. 3\n")
    code, err = _command(OSError(28, "No space left on device"), monkeypatch, capsys)
    assert code == 2 and "No space left on device" in err and "--debug" not in err


def test_bad_input_raises_a_project_error_that_is_also_the_builtin(tmp_path):
    for kind, builtin in [(MissingFileError, FileNotFoundError), (WrongFileError, ValueError),
                          (SettingError, ValueError), (TraceFileError, ValueError),
                          (LLMConfigError, ValueError), (EmptyDescriptionError, ValueError)]:
        assert issubclass(kind, DV2SError) and issubclass(kind, builtin)
    with pytest.raises(MissingFileError, match="no trace file"):
        EpisodeTrace.load(tmp_path / "none.json")
    (tmp_path / "t.json").write_text(json.dumps({"scenario": "x"}))
    with pytest.raises(TraceFileError, match="is not a dv2s episode trace"):
        EpisodeTrace.load(tmp_path / "t.json")
    with pytest.raises(MissingFileError, match="does not exist"):
        resolve_map(str(tmp_path / "none.xodr"))
    (tmp_path / "m.txt").write_text("x")
    with pytest.raises(WrongFileError, match="not an OpenDRIVE map"):
        resolve_map(str(tmp_path / "m.txt"))
    with pytest.raises(EmptyDescriptionError, match="the description is empty"):
        generate_rules("  ")
    with pytest.raises(LLMConfigError, match="is not an http"):
        ChatClient("ftp://x", "m")
