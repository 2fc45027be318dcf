"""Every error reaches the CLI user as one line and a non-zero exit; --debug shows the traceback."""

import json
from pathlib import Path

import pytest

from dv2s_gym import cli
from dv2s_gym.pipeline.errors import MissingAPIKeyError

EVALSET = Path(__file__).resolve().parents[1] / "dv2s_gym" / "evalset"


def _one_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def test_describe_with_the_openai_backend_and_no_key_is_one_line(capsys, monkeypatch):
    for var in ("OPENAI_API_KEY", "DV2S_VLM_API_KEY", "DV2S_VLM_BASE_URL", "DV2S_LLM_API_KEY", "DV2S_LLM_BASE_URL"):
        monkeypatch.delenv(var, raising=False)
    clip = sorted(EVALSET.glob("*.webm"))[0]
    assert cli.main(["describe", str(clip), "--dra", "openai"]) == 2
    line = _one_line(capsys)
    assert line.startswith("dv2s: error:") and "API key" in line and "OPENAI_API_KEY" in line
    with pytest.raises(MissingAPIKeyError):
        cli.main(["describe", str(clip), "--dra", "openai", "--debug"])


def test_unknown_scenario_is_one_line(capsys):
    assert cli.main(["run", "highway_lead_vehicle_brake", "--video", "x.webm"]) == 2
    line = _one_line(capsys)
    assert "unknown scenario" in line and "highway_lead_vehicle_brakes" in line


def test_an_unexpected_error_is_one_line_and_debug_shows_it(capsys, monkeypatch):
    def broken(args):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(cli, "_cmd_maps", broken)
    assert cli.main(["maps"]) == 1
    line = _one_line(capsys)
    assert "internal error: RuntimeError: boom second line" in line and "--debug" in line
    with pytest.raises(RuntimeError, match="boom"):
        cli.main(["--debug", "maps"])
    with pytest.raises(RuntimeError, match="boom"):
        cli.main(["maps", "--debug"])


@pytest.mark.parametrize("where", ["before", "between", "after"])
def test_bank_option_before_or_after_the_bank_subcommand(tmp_path, capsys, where):
    argv = {"before": ["--bank", str(tmp_path), "bank", "list", "--json"],
            "between": ["bank", "--bank", str(tmp_path), "list", "--json"],
            "after": ["bank", "list", "--json", "--bank", str(tmp_path)]}[where]
    assert cli.main(argv) == 0
    listing = json.loads(capsys.readouterr().out)
    assert listing == {"scenarios": [], "problems": {}}  # the empty bank, not the shipped one (21 entries)


def test_a_failed_generation_lists_only_what_it_wrote(tmp_path, capsys):
    out = tmp_path / "gen"
    code = cli.main(["generate", "zzz qqq", "--sg", "openai", "--api-key", "k", "--base-url", "http://127.0.0.1:9",
                     "--out", str(out)])
    assert code != 0
    text = capsys.readouterr().out
    listed = text.rsplit("written to", 1)[1]
    for name in ("scenario.scenic", "preview.webm"):
        assert not (out / name).exists() and name not in listed


def test_a_folder_that_is_not_a_bank_is_refused_as_such(tmp_path, capsys):
    from scenario_bank.bank import Bank, NotABankError

    for name in ("src", "docs", "build"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "notes.txt").write_text("not a scenario")
    with pytest.raises(NotABankError, match="not a scenario bank"):
        Bank(tmp_path)
    assert cli.main(["bank", "list", "--bank", str(tmp_path)]) == 2
    line = _one_line(capsys)
    assert "is not a scenario bank" in line and "broken" not in line
    assert len(Bank(tmp_path / "new")) == 0  # a new or empty folder starts a bank
