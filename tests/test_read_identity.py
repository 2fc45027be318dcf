"""What a plug-in reads at run time is part of a run's identity: a detector's threshold in a data file beside it, and
a helper module it imports only inside ``detect`` (only the worker processes import it). A changed one refuses a
resumed ``dv2s mine`` and a ``dv2s regress --baseline-report`` naming the file and both hashes; an unchanged rerun
resumes, and so does a run whose plug-in folder moved with the Python path. Two plug-ins' ``limits.json`` are two
files, each checked against its own; a file edited while a run runs stops it."""

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


FACT = {"limits": "user file limits.json read by myfail (SHA-256)", "helper": "user module speedhelp (SHA-256)"}


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
    assert FACT["helper"] in recorded and "module file units.py beside myfail (SHA-256)" in recorded
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


@pytest.mark.slow
def test_rerunning_a_finished_regression_keeps_the_files_its_detectors_read_in_its_report(tmp_path):
    """The documented resume of a finished run runs no worker: its rewritten report still names the file the
    detector read, so a baseline made of it is refused once the file changed."""
    changed = _plugins(tmp_path / "p", "limits")
    argv = ["regress", "--policy", "idm", "--baseline", "rule", "--scenarios", SCENARIO, "--episodes", "2",
            "--failure", "speeding", "--workers", "2", "--out", "base"]
    for _ in range(2):
        done = _dv2s(tmp_path / "p", tmp_path, *argv)
        assert done.returncode in (0, 3), done.stderr[-2000:]
        recorded = json.loads((tmp_path / "base" / "report.json").read_text())["code_identity"]
        assert recorded["files read by detectors"]["speeding"][FACT["limits"]] == run_identity.file_sha256(changed)
    _edit(changed)
    cand = _dv2s(tmp_path / "p", tmp_path, "regress", "--policy", "idm", "--baseline-report", "base/report.json",
                 "--failure", "speeding", "--workers", "2", "--out", "cand")
    assert cand.returncode == 2, cand.stderr[-2000:]
    assert "read files which differ here now" in cand.stderr


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


def test_installed_distributions_metadata_on_the_python_path_is_no_user_file(tmp_path, monkeypatch):
    """An editable install leaves ``<name>.egg-info`` beside the sources, on the Python path; looking up a version
    reads it, and a checkout's own metadata must not enter a run's identity."""
    folder = tmp_path / "checkout"
    for name in ("mine.egg-info", "other-1.0.dist-info"):
        (folder / name).mkdir(parents=True)
        (folder / name / "PKG-INFO").write_text("Name: x\n", encoding="utf-8")
    data = folder / "limits.json"
    data.write_text("{}", encoding="utf-8")
    monkeypatch.syspath_prepend(str(folder))
    read_files.watch()
    for path in (folder / "mine.egg-info" / "PKG-INFO", folder / "other-1.0.dist-info" / "PKG-INFO", data):
        path.read_text(encoding="utf-8")
    found = read_files.user_reads()
    assert str(data.resolve()) in found
    assert not any(".egg-info" in path or ".dist-info" in path for path in found)


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


# --------------------------------------------------------------------------- two plug-ins, each with its limits.json
def _kind_plugin(kind: str, severity: int) -> str:
    return LIMITS_PLUGIN.replace('"speeding"', repr(kind)).replace("sped", f"{kind}_flag").replace(
        "severity=5", f"severity={severity}")


def _two_plugins(base: Path) -> None:
    """``plug/myfail.py`` (kind ``speeding``, its ``limits.json`` 20) and ``plug4/myfail4.py`` (kind ``crawling``,
    its ``limits.json`` 1000), each reading the ``limits.json`` beside it."""
    for folder, module, kind, limit, severity in (("plug", "myfail", "speeding", 20.0, 5),
                                                  ("plug4", "myfail4", "crawling", 1000.0, 6)):
        (base / folder).mkdir(parents=True)
        (base / folder / f"{module}.py").write_text(_kind_plugin(kind, severity), encoding="utf-8")
        (base / folder / "limits.json").write_text(json.dumps({"speed": limit}), encoding="utf-8")
        (base / folder / "units.py").write_text(f"KMH = {limit}\n", encoding="utf-8")  # beside each: two names too


def _dv2s_two(base: Path, order: tuple, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DV2S_PLUGINS": "myfail,myfail4",
           "PYTHONPATH": os.pathsep.join([str(ROOT)] + [str(base / folder) for folder in order])}
    return subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *args], cwd=base, env=env, capture_output=True,
                          text=True, timeout=900)


TWO = {"speeding": "user file limits.json read by myfail (SHA-256)",
       "crawling": "user file limits.json read by myfail4 (SHA-256)"}


@pytest.mark.slow
@pytest.mark.parametrize("order", [("plug", "plug4"), ("plug4", "plug")])
def test_two_plugins_limits_files_are_two_names_each_checked_against_its_own_file(tmp_path, order):
    _two_plugins(tmp_path)
    sha = {kind: run_identity.file_sha256(tmp_path / folder / "limits.json")
           for kind, folder in (("speeding", "plug"), ("crawling", "plug4"))}
    regress = ("regress", "--policy", "idm", "--scenarios", SCENARIO, "--episodes", "2",
               "--failure", "speeding,crawling", "--workers", "2")
    first = _dv2s_two(tmp_path, order, *regress, "--baseline", "rule", "--out", "k1")
    assert first.returncode in (0, 3), first.stderr[-2000:]
    recorded = json.loads((tmp_path / "k1" / "run.json").read_text())["settings"]["code_identity"]
    assert {TWO[kind]: recorded.get(TWO[kind]) for kind in TWO} == {TWO[kind]: sha[kind] for kind in TWO}
    assert "module file units.py beside myfail (SHA-256)" in recorded
    assert "module file units.py beside myfail4 (SHA-256)" in recorded
    reads = json.loads((tmp_path / "k1" / "report.json").read_text())["code_identity"]["files read by detectors"]
    for kind in TWO:  # each kind's own limits.json (and its plug-in module), not the other's
        assert {key: value for key, value in reads[kind].items() if key.startswith("user file")} == {
            TWO[kind]: sha[kind]}
    shutil.copy(tmp_path / "k1" / "report.json", tmp_path / "base.json")  # as the first run wrote it
    again = _dv2s_two(tmp_path, order, *regress, "--baseline", "rule", "--out", "k1")  # nothing changed: resumes
    assert again.returncode in (0, 3), again.stderr[-2000:]
    same = _dv2s_two(tmp_path, order, *regress, "--baseline-report", "base.json", "--out", "k2")
    assert same.returncode in (0, 3), same.stderr[-2000:]
    (tmp_path / "plug" / "limits.json").write_text('{"speed": 1000.0}', encoding="utf-8")  # decides speeding
    now = run_identity.file_sha256(tmp_path / "plug" / "limits.json")
    resumed = _dv2s_two(tmp_path, order, *regress, "--baseline", "rule", "--out", "k1")
    assert resumed.returncode == 2
    assert f"{TWO['speeding']}: run has {sha['speeding'][:12]}, now {now[:12]}" in resumed.stderr
    cand = _dv2s_two(tmp_path, order, *regress, "--baseline-report", "base.json", "--out", "k3")
    assert cand.returncode == 2
    line = cand.stderr.strip().splitlines()[-1]
    assert "judged failure kind 'speeding' by a plug-in that read files which differ here now" in line
    assert f"{TWO['speeding']}: recorded {sha['speeding'][:12]}, now {now[:12]}" in line


def test_a_plugins_data_file_is_named_beside_the_module_that_read_it_and_found_there_again(tmp_path, monkeypatch):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / f"reader_{folder}.py").write_text("X = 1\n", encoding="utf-8")
        (tmp_path / folder / "limits.json").write_text(json.dumps({"folder": folder}), encoding="utf-8")
        monkeypatch.syspath_prepend(str(tmp_path / folder))
    reads = [read_files.ReadFile(str(tmp_path / folder / "limits.json"), None,
                                 run_identity.file_sha256(tmp_path / folder / "limits.json"),
                                 (read_files.plugin_label(f"reader_{folder}"),)) for folder in ("a", "b")]
    facts = run_identity.read_facts(reads)
    assert facts == {f"user file limits.json read by reader_{folder} (SHA-256)": read.sha256
                     for folder, read in zip("ab", reads)}
    assert run_identity.changed_files(facts) == []
    (tmp_path / "b" / "limits.json").write_text("{}", encoding="utf-8")
    assert [line.partition(":")[0] for line in run_identity.changed_files(facts)] == [
        "user file limits.json read by reader_b (SHA-256)"]
    unlabelled = [read_files.ReadFile(read.path, None, read.sha256, ()) for read in reads]  # read by no plug-in
    assert run_identity.read_facts(unlabelled) == {f"user file {Path(read.path).resolve()} (SHA-256)": read.sha256
                                                   for read in reads}  # one relative name for both: their paths
    with pytest.raises(read_files.ReadFilesError, match=r"two different files the code read would be recorded as "
                                                        r"'user module reader_a \(SHA-256\)'"):
        run_identity.read_facts([read_files.ReadFile(str((tmp_path / "a" / "reader_a.py").resolve()), "reader_a",
                                                     digest * 64, ()) for digest in "01"])


def test_a_file_whose_sha256_changes_while_a_pool_runs_stops_it_naming_the_file_and_both_hashes(tmp_path):
    from dv2s_gym.workers.pool import LocalBackend

    pool = LocalBackend(workers=1)
    path = str(tmp_path / "limits.json")
    pool._note_read(read_files.ReadFile(path, None, "a" * 64, ("detector speeding",)))
    pool._note_read(read_files.ReadFile(path, None, "a" * 64, ("plug-in myfail",)))
    assert pool.files_read[path].labels == ("detector speeding", "plug-in myfail")
    with pytest.raises(read_files.ReadFilesError, match=rf"{path} changed while the run ran \(SHA-256 aaaaaaaaaaaa "
                                                        r"-> bbbbbbbbbbbb\).*restore the file and resume"):
        pool._note_read(read_files.ReadFile(path, None, "b" * 64, ("detector speeding",)))


@pytest.mark.slow
def test_a_data_file_edited_while_a_mining_run_runs_stops_it_keeping_its_episodes(tmp_path):
    import time

    limits = _plugins(tmp_path / "p", "limits")
    before = run_identity.file_sha256(limits)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DV2S_PLUGINS": "myfail",
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path / "p" / "plugins"), str(tmp_path / "p" / "lib")])}
    def command(budget: int) -> list:
        return [sys.executable, "-m", "dv2s_gym.cli", "mine", "--policy", "idm", "--scenarios", SCENARIO, "--budget",
                str(budget), "--workers", "2", "--batch", "2", "--no-convert", "--no-progress", "--out", "run"]
    episodes = tmp_path / "run" / "episodes.jsonl"
    with subprocess.Popen(command(40), cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as run:
        deadline = time.monotonic() + 600
        while run.poll() is None and time.monotonic() < deadline and not (
                episodes.is_file() and len(episodes.read_text().splitlines()) >= 2):
            time.sleep(0.2)
        _edit(limits)  # the detector reads it again for every episode
        _, err = run.communicate(timeout=900)
    after = run_identity.file_sha256(limits)
    assert run.returncode == 2, err[-2000:]
    line = err.strip().splitlines()[-1]
    assert f"{limits.resolve()} changed while the run ran (SHA-256 {before[:12]} -> {after[:12]})" in line
    assert "restore the file and resume" in line
    kept = len(episodes.read_text().splitlines())
    assert 2 <= kept < 40
    recorded = json.loads((tmp_path / "run" / "settings.json").read_text())["code_identity"]
    assert recorded[FACT["limits"]] == before
    limits.write_text('{"speed": 20.0}', encoding="utf-8")  # restored: the run resumes where it stopped
    resumed = subprocess.run(command(kept + 2), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert len(episodes.read_text().splitlines()) == kept + 2
