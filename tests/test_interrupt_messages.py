"""What `dv2s` prints on Ctrl-C: a line of its own after any progress bar, and what was really kept."""

from __future__ import annotations

import argparse
import sys

from tqdm import tqdm

from dv2s_gym.cli.interrupts import episodes_kept_note, report_interrupted


def test_the_interrupted_line_starts_a_line_of_its_own_after_an_open_bar(capsys):
    bar = tqdm(total=10, file=sys.stderr, desc="mining", mininterval=0)
    bar.update(3)
    code = report_interrupted(argparse.Namespace(command="mine"), "a note")
    err = capsys.readouterr().err
    assert code == 130
    lines = err.replace("\r", "\n").split("\n")
    assert "dv2s: interrupted; a note" in lines
    assert not err.rstrip("\n").endswith("it/s]") and err.rstrip("\n").endswith("dv2s: interrupted; a note")
    assert bar.disable or bar not in getattr(tqdm, "_instances", ())  # closed: not redrawn at exit


def test_an_interrupted_run_says_what_it_kept(tmp_path):
    missing = episodes_kept_note(tmp_path / "out" / "episodes.jsonl")
    assert "no episode had finished, so nothing was kept" in missing and "kept in" not in missing
    (tmp_path / "episodes.jsonl").write_text('{"index": 0}\n{"index": 1}\n')
    note = episodes_kept_note(tmp_path / "episodes.jsonl")
    assert note.startswith(f"2 finished episodes are kept in {tmp_path / 'episodes.jsonl'}") and "resume" in note


def test_ctrl_c_of_mine_before_its_first_episode_does_not_claim_a_missing_file(tmp_path, capsys, monkeypatch):
    import dv2s_gym.mining.miner as miner
    from cli_helpers import run

    def interrupted(*args, **options):
        raise KeyboardInterrupt

    monkeypatch.setattr(miner, "mine", interrupted)
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--no-progress", "--no-convert",
                       "--out", tmp_path / "mine")
    assert code == 130 and "nothing was kept" in err and "episodes.jsonl" not in err
