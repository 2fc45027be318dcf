"""Path options (``--out``, ``--video``, ``--from``) are checked while the options are read: a folder that cannot be
made or a missing input file is one line naming the option, the path, the problem and the fix, before any work."""

from __future__ import annotations

import pytest

from cli_helpers import run as run_in_process
from dv2s_gym.cli import build_parser


def run(capsys, *argv):
    """``(exit code, stdout, stderr)``; an error found while the options are read exits as argparse does."""
    try:
        return run_in_process(capsys, *argv)
    except SystemExit as stop:
        captured = capsys.readouterr()
        return stop.code, captured.out, captured.err


@pytest.mark.parametrize("argv, option, path", [
    (["train", "--steps", "100", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["run", "highway_cut_in_from_left", "--video", "/proc/nope/x.webm"], "--video", "/proc/nope/x.webm"),
    (["generate", "a car brakes", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["regress", "--policy", "rule", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["generate", "--from", "missing_description.txt"], "--from", "missing_description.txt"),
    (["mine", "--budget", "1", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["loop", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["demo", "--out", "/proc/nope"], "--out", "/proc/nope"),
    (["replay", "trace.json", "--video", "/proc/nope/x.webm"], "--video", "/proc/nope/x.webm"),
])
def test_a_bad_path_option_fails_early_in_one_line(capsys, argv, option, path):
    code, out, err = run(capsys, *argv)
    line = err.strip().splitlines()[-1]  # argparse prints the usage line, then the error
    assert line.startswith("dv2s") and "error: " in line and "Traceback" not in err
    assert code == 2 and out == "" and "measuring" not in err
    assert option in line and path in line and "pass " in line and "Errno" not in line


@pytest.mark.parametrize("argv, default", [
    (["demo"], "out/demo"), (["mine", "--policy", "rule"], None), (["loop"], None), (["replay", "trace.json"], None),
])
def test_the_default_of_a_checked_path_option_still_parses(tmp_path, monkeypatch, argv, default):
    monkeypatch.chdir(tmp_path)
    args = build_parser().parse_args(argv)
    assert getattr(args, "out", getattr(args, "video", None)) == default
    assert list(tmp_path.iterdir()) == []  # checking the option creates nothing


def test_an_output_folder_where_a_file_is_is_refused(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run(capsys, "generate", "a car brakes", "--out", blocker / "sub")
    assert code == 2 and "is a file, not a folder" in err.strip().splitlines()[-1]


@pytest.mark.parametrize("argument", ["bad/missing.txt", "notes.md", "some/folder/file"])
def test_a_missing_file_given_as_the_description_suggests_from(capsys, tmp_path, monkeypatch, argument):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, "generate", argument)
    line = err.strip().splitlines()[-1]
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--from FILE" in line and argument in line
    assert not (tmp_path / "out").exists()  # nothing was generated


def test_episode_on_a_file_that_is_no_report_says_what_is_expected(capsys, tmp_path):
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text("{not json")
    code, _, err = run(capsys, "replay", corrupt, "--episode", "x")
    line = err.strip().splitlines()[-1]
    assert code == 2 and "is an episode trace" not in line and "dv2s regress" in line and "report.json" in line


def test_missing_trace_archive_and_eval_folder_messages_name_the_fix(capsys, tmp_path):
    code, _, err = run(capsys, "replay", tmp_path / "missing.json")
    assert code == 2 and "no trace file" in err and "check the path" in err
    bad = tmp_path / "bad.webm"
    bad.write_bytes(b"\x1f\x8b\x08")
    code, _, err = run(capsys, "bank", "--bank", tmp_path / "bank", "import", bad)
    assert code == 2 and "not a readable bank archive" in err and "dv2s bank export" in err
    code, _, err = run(capsys, "eval", "sg", tmp_path / "nonexistent")
    assert code == 2 and "does not exist" in err and "label file" in err
