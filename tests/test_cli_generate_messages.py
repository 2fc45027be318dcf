"""``dv2s generate``'s result lines: each warning once, a nonzero exit when nothing of the description could be
placed, and a partial description still generated with its warnings."""

from __future__ import annotations

import json
import re

from cli_helpers import one_line_error, run
from disk_helpers import fill_disk_after


def test_a_description_of_which_nothing_is_placed_exits_1_with_the_fix(capsys, tmp_path):
    code, out, _ = run(capsys, "generate", "xyzzy plugh", "--out", tmp_path / "gen", "--seconds", 2)
    assert code == 1
    assert "nothing of the description could be placed" in out and "e.g. 'on a highway" in out
    assert "SP:" not in out  # a score of nothing against nothing says nothing
    assert "could not place: could not place" not in out


def test_a_partly_placed_description_is_generated_with_each_warning_once(capsys, tmp_path):
    text = "on a highway, a car ahead of the ego brakes suddenly while the sun sets behind the hills"
    code, out, _ = run(capsys, "generate", text, "--out", tmp_path / "gen", "--seconds", 2)
    warnings = json.loads((tmp_path / "gen" / "report.json").read_text())["generation"]["warnings"]
    assert code == 0 and warnings
    for warning in warnings:
        assert out.count(f"warning: {warning}\n") == 1
    assert "could not place: could not place" not in out
    assert re.search(r"\nSP: [01]\.\d\d \(of the parts of the description that were placed\)\n", out), out
    assert "nothing of the description could be placed" not in out


def test_a_fully_placed_description_has_no_warning(capsys, tmp_path):
    code, out, _ = run(capsys, "generate", "on a highway, a car ahead of the ego brakes suddenly",
                       "--out", tmp_path / "gen")  # the check runs long enough to see the braking
    assert code == 0 and "warning:" not in out and "\nSP: 1.00\n" in out


def test_a_full_disk_leaves_no_folder_and_no_earlier_result_changed(capsys, tmp_path, monkeypatch):
    text = "on a highway, a car ahead of the ego brakes suddenly"
    code, _, _ = run(capsys, "generate", text, "--out", tmp_path / "gen", "--seconds", 2)
    assert code == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "gen").iterdir()}
    fill_disk_after(monkeypatch, allowed=100)  # description.txt fits, elements.json does not
    code, out, err = run(capsys, "generate", "on a highway, a truck cuts in", "--out", tmp_path / "gen",
                         "--seconds", 2)
    line = one_line_error(err)
    assert code != 0 and "disk is full" in line and str(tmp_path / "gen") in line and ".tmp" not in line
    assert {p.name: p.read_bytes() for p in (tmp_path / "gen").iterdir()} == before
    code, _, err = run(capsys, "generate", text, "--out", tmp_path / "new" / "gen", "--seconds", 2)
    assert code != 0 and "disk is full" in one_line_error(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen"]  # neither new/ nor a temporary folder is left
