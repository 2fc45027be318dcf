"""Status lines printed while a progress bar is open start a line of their own."""

from __future__ import annotations

import sys

from tqdm import tqdm

from dv2s_gym.progress_lines import log_line


def test_a_status_line_is_not_glued_to_an_open_bar(capsys):
    with tqdm(total=10, file=sys.stderr, desc="DAgger fine-tune", mininterval=0) as bar:
        bar.update(4)
        log_line("DAgger iteration 2/4: beta 0.5")
        bar.update(1)
    lines = capsys.readouterr().err.replace("\r", "\n").split("\n")
    assert "DAgger iteration 2/4: beta 0.5" in lines


def test_without_a_bar_it_is_a_plain_line(capsys):
    log_line("round 1 [1/8] mining failures ...")
    assert capsys.readouterr().err == "round 1 [1/8] mining failures ...\n"
