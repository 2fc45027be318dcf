"""``dv2s maps``: lists the shipped maps; ``--build`` writes a fresh copy only into the ``--out`` folder given and
never into the installed package."""

from __future__ import annotations

import pytest

from cli_helpers import one_line_error, run
from scenario_bank.maps import MAPS_DIR, list_maps


def test_maps_lists_the_shipped_maps(capsys):
    code, out, _ = run(capsys, "maps")
    assert code == 0 and [line.split("\t")[0] for line in out.splitlines()] == list_maps()


@pytest.mark.parametrize("argv, words", [
    (["maps", "--build"], "--build needs --out DIR"),
    (["maps", "--build", "--out", str(MAPS_DIR)], "is the installed package's own maps folder"),
    (["maps", "--out", "somewhere"], "add --build"),
])
def test_build_refuses_the_package_folder_and_needs_out(argv, words, capsys):
    before = {path.name: path.stat().st_mtime_ns for path in MAPS_DIR.glob("*.xodr")}
    code, _, err = run(capsys, *argv)
    assert code == 2 and words in one_line_error(err)
    assert {path.name: path.stat().st_mtime_ns for path in MAPS_DIR.glob("*.xodr")} == before


def test_build_writes_the_same_maps_into_out(tmp_path, capsys):
    out = tmp_path / "maps"
    code, printed, _ = run(capsys, "maps", "--build", "--out", str(out))
    assert code == 0 and sorted(line.split("\t")[0] for line in printed.splitlines()) == sorted(list_maps())
    for name in list_maps():
        assert (out / f"{name}.xodr").read_bytes() == (MAPS_DIR / f"{name}.xodr").read_bytes()
