"""The command line's behaviour, recorded: what ``dv2s regress`` and ``dv2s mine`` write at a tiny scale.

``tests/data/behaviour/reports.json`` holds, for each of the runs in :data:`RUNS` (built-in drivers, a few
scenarios, one worker), the exit status and SHA-256 digests of the command's standard output and of every file it
writes: each JSON file's top-level fields one digest each, each JSON-lines file one digest per line, a trace's JSON
inside its gzip, other text and binary files whole. The mining run that converts also records the entries it adds
to its (copied) bank. What changes from run to run (times, durations, the machine, the installed version, digests
of the code, absolute paths, a video container's id and date, a checkpoint's MAC) is taken out first by the
normaliser in ``tests/behaviour_digest.py``, whose docstring lists its rules; the runs set ``PYTHONHASHSEED=0``.

A refactor must leave every digest as it is; a change of behaviour meant to be one changes them, and is recorded
by writing them again:

    .venv/bin/python tests/test_behaviour_reports.py --write
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, Optional

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from behaviour_digest import (differences, digest, file_digests, folder_digests, normalise_text,  # noqa: E402
                              require_the_jail, write_record)

RECORD = ROOT / "tests" / "data" / "behaviour" / "reports.json"
SHIPPED_BANK = ROOT / "scenario_bank" / "scenarios"

RUNS = {
    "regress": ["regress", "--policy", "keep_lane", "--baseline", "rule", "--scenarios", "highway_cut_in_from_left",
                "urban_pedestrian_crossing", "highway_lead_vehicle_brakes", "--episodes", "2"],
    "mine": ["mine", "--policy", "keep_lane", "--scenarios", "highway_cut_in_from_left", "urban_pedestrian_crossing",
             "highway_lead_vehicle_brakes", "--budget", "8", "--no-convert"],
    "mine-convert": ["mine", "--policy", "keep_lane", "--scenarios", "highway_lead_vehicle_brakes",
                     "urban_pedestrian_crossing", "--budget", "6", "--max-conversions", "1", "-k", "3",
                     "--bank", "{bank}"],
}
"""``dv2s`` arguments of each recorded run; every run adds ``--workers 1 --no-progress --out {out}``, and
``{bank}`` is a copy of the shipped bank the run may add to."""


def _run(name: str, argv: list, work: Path, workers: int = 1,
         adjust: Optional[Callable[[Path], None]] = None) -> Dict[str, Any]:
    out, bank = work / name / "out", work / name / "bank"
    shutil.copytree(SHIPPED_BANK, bank)
    shipped = {entry.name for entry in bank.iterdir()}
    argv = [part.format(bank=bank) for part in argv] + ["--workers", str(workers), "--no-progress",
                                                           "--out", str(out)]
    environment = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    done = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *argv], cwd=work, env=environment,
                          capture_output=True, text=True, timeout=900)
    if adjust is not None:
        adjust(out)
    places = {str(out): "<out>", str(bank): "<bank>", str(ROOT): "<repo>"}
    added = {entry.name: folder_digests(entry, places) if entry.is_dir() else file_digests(entry, places)
             for entry in sorted(bank.iterdir()) if entry.name not in shipped}
    return {"exit": done.returncode, "stdout": digest(normalise_text(done.stdout, places)),
            "files": folder_digests(out, places), "bank added": added}


def behaviour() -> Dict[str, Dict[str, Any]]:
    """``{run: {exit, stdout, files, bank added}}`` for every run of :data:`RUNS`, each in a fresh folder."""
    require_the_jail("the recorded mining runs")
    with tempfile.TemporaryDirectory(prefix="dv2s-behaviour-") as work:
        return {name: _run(name, argv, Path(work)) for name, argv in RUNS.items()}


@pytest.mark.slow
def test_regress_and_mine_write_the_reports_they_wrote():
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))
    now = behaviour()
    assert set(now) == set(recorded) == set(RUNS), "runs added or gone: write the record again"
    changed = differences(recorded, now)
    assert not changed, (f"{len(changed)} digest(s) of the reports differ: {changed[:12]}; if the change is meant, "
                         "record it: python tests/test_behaviour_reports.py --write")


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    write_record(RECORD, behaviour)
