"""What a plug-in reads at run time is part of a run's identity: a detector's threshold in a data file beside it, and
a helper module it imports only inside ``detect`` (only the worker processes import it). A changed one refuses a
resumed ``dv2s mine`` and a ``dv2s regress --baseline-report`` naming the file and both hashes; an unchanged rerun
resumes, and so does a run whose plug-in folder moved with the Python path."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from policies import run_identity
from scenario_bank import read_files

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "highway_lead_vehicle_brakes"

LIMITS_PLUGIN = '''
import json
from pathlib import Path

from dv2s_gym.mining.monitors import Detector, Failure, register_detector
from scenario_bank.failure_types import FailureType, register_failure_type


def detect(result, trace, settings):
    limit = float(json.loads(Path(__file__).with_name("limits.json").read_text())["speed"])
    for step, state in enumerate(trace.states):
        ego = state.get("ego")
        if ego and ego[3] > limit:
            return Failure("speeding", step * 0.2, step)
    return None


register_failure_type(FailureType("speeding", severity=5, result_field="sped", regress_default=False,
                                  with_actor=False, label="speeding"))
register_detector(Detector("speeding", detect, lambda result, failure, settings: -0.5))
'''

HELPER_PLUGIN = '''
from dv2s_gym.mining.monitors import Detector, Failure, register_detector
from scenario_bank.failure_types import FailureType, register_failure_type


def detect(result, trace, settings):
    from speedhelp import LIMIT  # imported where it is used: by the workers only
    for step, state in enumerate(trace.states):
        ego = state.get("ego")
        if ego and ego[3] > LIMIT:
            return Failure("speeding", step * 0.2, step)
    return None


register_failure_type(FailureType("speeding", severity=5, result_field="sped", regress_default=False,
                                  with_actor=False, label="speeding"))
register_detector(Detector("speeding", detect, lambda result, failure, settings: -0.5))
'''


def _plugins(base: Path, road: str) -> Path:
    """A plug-in folder (``plugins/``) and a helper folder (``lib/``) under ``base``; the file whose edit changes
    what the detector counts."""
    (base / "plugins").mkdir(parents=True)
    (base / "lib").mkdir()
    (base / "plugins" / "units.py").write_text("KMH = 3.6\n", encoding="utf-8")  # a .py file beside the plug-in
    if road == "limits":
        (base / "plugins" / "myfail.py").write_text(LIMITS_PLUGIN, encoding="utf-8")
        (base / "plugins" / "limits.json").write_text('{"speed": 20.0}', encoding="utf-8")
        return base / "plugins" / "limits.json"
    (base / "plugins" / "myfail.py").write_text(HELPER_PLUGIN, encoding="utf-8")
    (base / "lib" / "speedhelp.py").write_text("LIMIT = 20.0\n", encoding="utf-8")
    return base / "lib" / "speedhelp.py"


def _dv2s(base: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DV2S_PLUGINS": "myfail",
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(base / "plugins"), str(base / "lib")])}
    return subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)


def _mine(base: Path, cwd: Path, budget: int) -> subprocess.CompletedProcess:
    return _dv2s(base, cwd, "mine", "--policy", "idm", "--scenarios", SCENARIO, "--budget", str(budget),
                 "--workers", "2", "--no-convert", "--out", "run")


def _edit(path: Path) -> None:
    path.write_text('{"speed": 1000.0}' if path.suffix == ".json" else "LIMIT = 1000.0\n", encoding="utf-8")


FACT = {"limits": "user file limits.json (SHA-256)", "helper": "user module speedhelp (SHA-256)"}


@pytest.mark.slow
@pytest.mark.parametrize("road", ["limits", "helper"])
def test_a_mining_resume_after_a_file_the_detector_read_changed_is_refused_naming_it(tmp_path, road):
    changed = _plugins(tmp_path / "p", road)
    first = _mine(tmp_path / "p", tmp_path, 2)
    assert first.returncode == 0, first.stderr[-2000:]
    recorded = json.loads((tmp_path / "run" / "settings.json").read_text())["code_identity"]
    assert recorded[FACT[road]] == run_identity.file_sha256(changed)
    before = recorded[FACT[road]]
    _edit(changed)
    again = _mine(tmp_path / "p", tmp_path, 4)
    assert again.returncode == 2
    line = again.stderr.strip().splitlines()[-1]
    assert "holds a mining run made with other code (files the code read differ: " in line
    assert f"{FACT[road]}: run has {before[:12]}, now {run_identity.file_sha256(changed)[:12]}" in line
    assert "start a new --out folder" in line
    assert len((tmp_path / "run" / "episodes.jsonl").read_text().splitlines()) == 2


@pytest.mark.slow
def test_an_unchanged_rerun_resumes_and_so_does_one_whose_plugin_folders_moved(tmp_path):
    _plugins(tmp_path / "p", "helper")
    (tmp_path / "p" / "plugins" / "limits.json").write_text('{"speed": 20.0}', encoding="utf-8")
    assert _mine(tmp_path / "p", tmp_path, 2).returncode == 0
    again = _mine(tmp_path / "p", tmp_path, 3)
    assert again.returncode == 0, again.stderr[-2000:]
    shutil.move(str(tmp_path / "p"), str(tmp_path / "moved"))
    moved = _mine(tmp_path / "moved", tmp_path, 4)
    assert moved.returncode == 0, moved.stderr[-2000:]
    assert len((tmp_path / "run" / "episodes.jsonl").read_text().splitlines()) == 4
    recorded = json.loads((tmp_path / "run" / "settings.json").read_text())["code_identity"]
    assert FACT["helper"] in recorded and "module file units.py (SHA-256)" in recorded
    assert not any(str(tmp_path) in key for key in recorded)
    _edit(tmp_path / "moved" / "lib" / "speedhelp.py")  # moved, then changed: still refused
    assert _mine(tmp_path / "moved", tmp_path, 5).returncode == 2


@pytest.mark.slow
@pytest.mark.parametrize("road", ["limits", "helper"])
def test_a_baseline_report_whose_detector_read_a_file_changed_since_is_refused(tmp_path, road):
    changed = _plugins(tmp_path / "p", road)
    base = _dv2s(tmp_path / "p", tmp_path, "regress", "--policy", "idm", "--baseline", "rule", "--scenarios",
                 SCENARIO, "--episodes", "2", "--failure", "speeding", "--workers", "2", "--out", "base")
    assert base.returncode in (0, 3), base.stderr[-2000:]
    recorded = json.loads((tmp_path / "base" / "report.json").read_text())["code_identity"]
    assert recorded["files read by detectors"]["speeding"][FACT[road]] == run_identity.file_sha256(changed)
    same = _dv2s(tmp_path / "p", tmp_path, "regress", "--policy", "idm", "--baseline-report", "base/report.json",
                 "--failure", "speeding", "--workers", "2", "--out", "same")
    assert "read files which differ" not in same.stderr and (tmp_path / "same" / "report.json").is_file()
    _edit(changed)
    cand = _dv2s(tmp_path / "p", tmp_path, "regress", "--policy", "idm", "--baseline-report", "base/report.json",
                 "--failure", "speeding", "--workers", "2", "--out", "cand")
    assert cand.returncode == 2
    line = cand.stderr.strip().splitlines()[-1]
    assert "judged failure kind 'speeding' by a plug-in that read files which differ here now" in line
    assert f"{FACT[road]}: recorded " in line and "rerun the baseline" in line
    assert not (tmp_path / "cand" / "report.json").exists()


# --------------------------------------------------------------------------- the watcher and the names, in process
def test_a_file_read_in_a_labelled_block_is_a_user_file_with_that_label(tmp_path, monkeypatch):
    folder = tmp_path / "plugs"
    folder.mkdir()
    data = folder / "table.csv"
    data.write_text("a,b\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(folder))
    read_files.watch()
    with read_files.reading_for(read_files.detector_label("probe")):
        data.read_text(encoding="utf-8")
    (folder / "written.txt").write_text("x", encoding="utf-8")  # written, not read: not the run's input
    found = read_files.user_reads()
    assert found[str(data.resolve())].labels == ("detector probe",)
    assert found[str(data.resolve())].sha256 == run_identity.file_sha256(data)
    assert str((folder / "written.txt").resolve()) not in found
    assert not any(path.startswith(sys.prefix) for path in found)
    facts = run_identity.read_facts([found[str(data.resolve())]])
    assert facts == {"user file table.csv (SHA-256)": run_identity.file_sha256(data)}
    assert read_files.user_reads(exclude=[folder]).get(str(data.resolve())) is None


def test_a_recorded_user_file_is_found_again_relative_to_the_python_path(tmp_path, monkeypatch):
    old, new = tmp_path / "old", tmp_path / "new"
    old.mkdir()
    (old / "limits.json").write_text("{}", encoding="utf-8")
    key = "user file limits.json (SHA-256)"
    recorded = {key: run_identity.file_sha256(old / "limits.json")}
    monkeypatch.syspath_prepend(str(old))
    assert run_identity.changed_files(recorded) == []
    sys.path.remove(str(old))  # the folder moves, and the Python path with it (monkeypatch restores sys.path)
    shutil.move(str(old), str(new))
    assert run_identity.changed_files(recorded)[0].endswith("now missing")
    monkeypatch.syspath_prepend(str(new))
    assert run_identity.changed_files(recorded) == []
    (new / "limits.json").write_text('{"speed": 1}', encoding="utf-8")
    assert run_identity.changed_files(recorded) == [
        f"{key}: recorded {recorded[key][:12]}, now {run_identity.file_sha256(new / 'limits.json')[:12]}"]


def test_the_files_a_pools_workers_read_are_added_to_the_runs_record_as_they_appear(tmp_path, monkeypatch):
    folder, run = tmp_path / "plugs", tmp_path / "run"
    folder.mkdir()
    run.mkdir()
    monkeypatch.syspath_prepend(str(folder))
    (folder / "limits.json").write_text("{}", encoding="utf-8")
    (run / "own.json").write_text("{}", encoding="utf-8")
    record = run / "run.json"
    record.write_text(json.dumps({"settings": {"code_identity": {"dv2s sources (SHA-256)": "x"}}}), encoding="utf-8")

    class Pool:
        files_read = {}

    recorder = run_identity.ReadsRecorder(record, Pool, exclude=[run], where=["settings"])
    for path in (folder / "limits.json", run / "own.json"):
        Pool.files_read[str(path)] = read_files.ReadFile(str(path), None, run_identity.file_sha256(path),
                                                         ("detector probe",))
    recorder.record()
    identity = json.loads(record.read_text())["settings"]["code_identity"]
    assert identity["user file limits.json (SHA-256)"] == run_identity.file_sha256(folder / "limits.json")
    assert identity["dv2s sources (SHA-256)"] == "x" and not any("own.json" in key for key in identity)
    written = record.stat().st_mtime_ns
    recorder.record()  # nothing new: the record is not written again
    assert record.stat().st_mtime_ns == written
    (folder / "limits.json").write_text('{"speed": 1}', encoding="utf-8")
    with pytest.raises(ValueError, match=r"files the code read differ: user file limits\.json \(SHA-256\): run has "):
        run_identity.check_code_unchanged({"code_identity": identity}, run="run holds a run", error=ValueError,
                                          now={"dv2s sources (SHA-256)": "x"})
