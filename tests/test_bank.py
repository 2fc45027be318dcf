"""The scenario bank as a product: API, dedup, atomic writes, concurrency, bad sidecars, versions."""

import errno
import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import envs  # noqa: F401  (adding to a bank checks the script in the simulator, which importing envs loads)
from scenario_bank.bank import (
    BANK_VERSION,
    Bank,
    BankError,
    DuplicateScenarioError,
    WRITERS_LOCK,
    UnknownScenarioError,
    Sidecar,
    content_hash,
)
from scenario_bank.cache import CACHE_ENV

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = textwrap.dedent(
    """\
    param map = 'highway_straight'
    model scenic.domains.driving.model
    param gap = Range(10, 30)
    lane = Uniform(*network.lanes)
    ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
    lead = new Car following roadDirection from ego for globalParameters.gap,
        with behavior FollowLaneBehavior(target_speed={speed})
    """
)
ELEMENTS = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "keep_lane"]],
            "relations": [["car", "ahead_of", "ego"]]}


def script(speed: int = 15, extra: str = "") -> str:
    return SCRIPT.format(speed=speed) + extra


def add(bank: Bank, name: str, speed: int = 15, **kw) -> object:
    kw.setdefault("elements", ELEMENTS)
    kw.setdefault("tags", ["highway", "test"])
    extra = kw.pop("extra", "")
    kw["source"] = kw.pop("provenance", None)
    return bank.add(script(speed, extra), Sidecar(description=f"A car ahead of the ego ({name}).", name=name, **kw))


@pytest.fixture
def bank(tmp_path):
    return Bank(tmp_path / "bank")


@pytest.mark.slow
def test_add_get_list_filter_remove(bank):
    entry = add(bank, "lead_slow", provenance={"kind": "generated", "video": "v.mp4", "generator": "rules",
                                               "model": None, "context_hash": "abc", "seed": 3})
    assert entry.name == "lead_slow" and entry.map == "highway_straight"
    assert entry.content_hash == content_hash(entry.script)
    assert entry.source.kind == "generated" and entry.source.video == "v.mp4" and entry.source.date
    add(bank, "lead_fast", speed=30, tags=["highway", "fast"],
        elements={**ELEMENTS, "actions": [["car", "brake"]]})
    reopened = Bank(bank.root)
    assert reopened.names() == ["lead_fast", "lead_slow"]
    assert [e.name for e in reopened.list(tag="fast")] == ["lead_fast"]
    assert [e.name for e in reopened.list(element="car:brake")] == ["lead_fast"]
    assert [e.name for e in reopened.list(element="brake")] == ["lead_fast"]
    assert [e.name for e in reopened.list(text="LEAD_SLOW")] == ["lead_slow"]
    assert [e.name for e in reopened.list(source="generated")] == ["lead_slow"]
    assert len(reopened.list(element=["highway", "ahead_of"])) == 2
    reopened.remove("lead_slow")
    assert Bank(bank.root).names() == ["lead_fast"]
    with pytest.raises(UnknownScenarioError, match="lead_fast"):
        Bank(bank.root).get("lead_fas")


@pytest.mark.slow
def test_duplicates_are_refused_with_the_existing_name(bank):
    add(bank, "original")
    with pytest.raises(DuplicateScenarioError, match="original") as exc:
        bank.add(script(), Sidecar(description="same bytes", name="copy", elements=ELEMENTS))
    assert exc.value.existing == "original"
    # Same elements and same parameter ranges, different text (speed literal, comment): semantic duplicate.
    with pytest.raises(DuplicateScenarioError, match="semantically identical.*original"):
        bank.add(script(16, "# another comment\n"), Sidecar(description="reworded", name="reworded", elements=ELEMENTS))
    # Different parameter range: a new scenario.
    other = script().replace("Range(10, 30)", "Range(5, 12)")
    assert bank.add(other, Sidecar(description="closer lead", name="closer", elements=ELEMENTS)).name == "closer"


@pytest.mark.slow
def test_scripts_whose_elements_name_nothing_compare_by_their_bytes_shared_parameters_and_code(bank):
    """A hand-added script without elements says nothing of its scene: two different such scripts on one map are no
    semantic duplicates whatever their params; they are one family (a near-duplicate warning) through a parameter in
    common whose ranges overlap, or when their code is at most two lines apart (a near-copy); another program without
    a parameter in common is not alike at all."""
    import warnings
    from scenario_bank.errors import NearDuplicateWarning

    empty = {"road": None, "participants": [], "actions": [], "relations": []}
    slow = SCRIPT.replace("param gap = Range(10, 30)\n", "").replace("globalParameters.gap", "Range(10, 30)")
    bank.add(slow.format(speed=15), Sidecar(description="a slow car ahead", name="slow_car", elements=empty))
    with pytest.warns(NearDuplicateWarning, match="slow_car"):  # one line apart: a near-copy
        assert bank.add(slow.format(speed=0), Sidecar(description="a stopped car", name="stopped_car",
                                                      elements=empty)).name == "stopped_car"
    with pytest.raises(DuplicateScenarioError, match="byte-for-byte identical.*slow_car"):
        bank.add(slow.format(speed=15), Sidecar(description="the same bytes", name="again", elements=empty))
    crowd = (slow.format(speed=15) + "behind = new Car following roadDirection from ego for -15\n"
             + "far = new Car following roadDirection from ego for 60\n"
             + "farther = new Car following roadDirection from ego for 90\n")
    with warnings.catch_warnings():  # three lines more and no parameter in common: not alike
        warnings.simplefilter("error", NearDuplicateWarning)
        assert bank.add(crowd, Sidecar(description="cars ahead and behind", name="crowd",
                                       elements=empty)).name == "crowd"
    # with a parameter in common whose ranges overlap, they are near-duplicates: one scenario family
    bank.add(script(15), Sidecar(description="a lead at a gap", name="gap_lead", elements=empty))
    with pytest.warns(NearDuplicateWarning, match="gap_lead"):
        bank.add(script(5).replace("Range(10, 30)", "Range(20, 40)"),
                 Sidecar(description="a slower lead at a gap", name="gap_lead_slow", elements=empty))
    with pytest.warns(NearDuplicateWarning, match="gap_lead"):  # ranges apart, but two lines of code: a near-copy
        assert bank.add(script(5).replace("Range(10, 30)", "Range(50, 60)"),
                        Sidecar(description="a slower lead far off", name="gap_far", elements=empty)).name == "gap_far"


@pytest.mark.slow
def test_bad_input_to_add(bank):
    with pytest.raises(BankError, match="description"):
        bank.add(script(), Sidecar(description=" ", name="x"))
    with pytest.raises(BankError, match="unknown action"):
        bank.add(script(), Sidecar(description="d", name="x", elements={"actions": [["car", "fly"]]}))
    with pytest.raises(BankError, match="invalid scenario name"):
        bank.add(script(), Sidecar(description="d", name="Bad Name!"))
    with pytest.raises(BankError, match="provenance kind"):
        bank.add(script(), Sidecar(description="d", name="x", source={"kind": "stolen"}))
    with pytest.raises(ValueError, match="safety check.*import os"):
        bank.add(script(extra="import os\n"), Sidecar(description="d", name="x"))
    assert len(Bank(bank.root)) == 0


@pytest.mark.slow
def test_sample_by_weights_and_stats(bank):
    for k in range(3):
        add(bank, f"s{k}", speed=10 + k, extra=f"param p{k} = Range({k}, {k + 1})\n")
    counts = {n: 0 for n in bank.names()}
    for seed in range(300):
        counts[bank.sample(seed, weights={"s0": 0.0, "s1": 1.0, "s2": 3.0}).name] += 1
    assert counts["s0"] == 0 and counts["s2"] > 2 * counts["s1"] > 0
    assert bank.sample(1).name == bank.sample(1).name
    with pytest.raises(BankError, match="weights"):
        bank.sample(0, weights={"s0": 0.0})
    stats = bank.stats()
    assert stats["scenarios"] == 3 and stats["by_map"] == {"highway_straight": 3}


@pytest.mark.slow
def test_export_import_and_diff(bank, tmp_path):
    add(bank, "a", speed=11)
    add(bank, "b", speed=12, extra="param q = Range(1, 2)\n")
    archive = bank.export(tmp_path / "bank.tar.gz")
    other = Bank(tmp_path / "other")
    result = other.import_archive(archive)
    assert sorted(result["added"]) == ["a", "b"] and result["skipped"] == []
    assert bank.diff(other).identical
    again = other.import_archive(archive)
    assert again == {"added": [], "skipped": ["a", "b"]}
    with pytest.raises(DuplicateScenarioError):
        other.import_archive(archive, on_duplicate="error")
    other.remove("a")
    add(other, "c", speed=13, extra="param r = Range(3, 4)\n")
    diff = bank.diff(other)
    assert diff.only_in_first == ["a"] and diff.only_in_second == ["c"] and diff.same == ["b"]


@pytest.mark.slow
def test_import_of_a_corrupt_or_foreign_archive_changes_nothing(bank, tmp_path):
    add(bank, "keep")
    garbage = tmp_path / "garbage.tar.gz"
    garbage.write_bytes(b"not an archive at all")
    with pytest.raises(BankError, match="not a readable bank archive"):
        bank.import_archive(garbage)
    assert Bank(bank.root).names() == ["keep"]
    assert [p.name for p in bank.root.iterdir() if p.name.startswith(".")] == [WRITERS_LOCK]  # no staging left


@pytest.mark.slow
def test_bad_sidecars_are_reported_and_the_rest_stays_usable(bank):
    for k, name in enumerate(("good", "corrupt", "edited", "missing")):
        add(bank, name, speed=k, extra=f"param {name} = Range(0, {k + 1})\n")
    (bank.root / "corrupt" / "meta.json").write_text("{ not json")
    meta = json.loads((bank.root / "edited" / "meta.json").read_text())
    meta["elements"]["actions"] = [["car", "teleport"]]
    (bank.root / "edited" / "meta.json").write_text(json.dumps(meta))
    (bank.root / "missing" / "meta.json").unlink()
    reopened = Bank(bank.root)
    assert reopened.names() == ["good"]
    assert set(reopened.problems) == {"corrupt", "edited", "missing"}
    assert "teleport" in reopened.problems["edited"] and "missing sidecar" in reopened.problems["missing"]
    with pytest.raises(UnknownScenarioError, match="unusable"):
        reopened.get("corrupt")


def test_a_sidecar_with_a_malformed_story_is_reported_with_the_fix(bank):
    add(bank, "told")
    meta = json.loads((bank.root / "told" / "meta.json").read_text())
    meta["story"] = {"actors": {"cutter": "car"}, "steps": [{"actor": "cuter", "action": "cut_in"}]}
    (bank.root / "told" / "meta.json").write_text(json.dumps(meta))
    problem = Bank(bank.root).problems["told"]
    assert "'cuter'" in problem and "story.actors" in problem
    meta["story"]["steps"][0]["actor"] = "cutter"
    (bank.root / "told" / "meta.json").write_text(json.dumps(meta))
    assert Bank(bank.root).get("told").sidecar.story["actors"] == {"cutter": "car"}


def index_path(bank):
    """The bank's index in the user cache directory."""
    return bank._cache_folder() / "index.json"


def test_newer_versions_are_refused(bank):
    add(bank, "x")
    index = json.loads(index_path(bank).read_text())
    index["version"] = BANK_VERSION + 1  # a newer dv2s-gym's cache is only a cache: rebuilt
    index_path(bank).write_text(json.dumps(index))
    assert Bank(bank.root).names() == ["x"]
    assert json.loads(index_path(bank).read_text())["version"] == BANK_VERSION
    meta = json.loads((bank.root / "x" / "meta.json").read_text())
    meta["schema_version"] = 99
    (bank.root / "x" / "meta.json").write_text(json.dumps(meta))
    assert "newer" in Bank(bank.root).problems["x"]


@pytest.mark.slow
def test_full_disk_mid_write_leaves_the_bank_unchanged(bank, monkeypatch):
    add(bank, "before")
    real_fsync = os.fsync
    calls = {"n": 0}

    def failing_fsync(fd):
        calls["n"] += 1
        if calls["n"] == 2:  # the sidecar of the new entry
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(BankError, match="disk is full.*unchanged"):
        add(bank, "during", speed=40, extra="param z = Range(7, 8)\n")
    monkeypatch.setattr(os, "fsync", real_fsync)
    reopened = Bank(bank.root)
    assert reopened.names() == ["before"] and not reopened.problems
    assert not list(bank.root.glob(".staging-*"))


_WRITER = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {root!r})
    import envs  # the simulator the bank checks the script in
    from scenario_bank.bank import Bank, Sidecar
    import scenario_bank.bank as bank_module
    bank = Bank({bank!r})
    real_commit = bank_module.Bank._commit
    def slow_commit(self, staging, name):
        print("staged", flush=True)
        time.sleep(30)  # killed here, between writing the entry and renaming it in
        real_commit(self, staging, name)
    bank_module.Bank._commit = slow_commit
    bank.add({script!r}, Sidecar(description="killed while adding", name="victim"))
    """
)


@pytest.mark.slow
def test_killed_writer_leaves_the_bank_as_it_was(bank):
    add(bank, "before")
    code = _WRITER.format(root=str(ROOT), bank=str(bank.root), script=script(33, "param k = Range(1, 9)\n"))
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "staged"
    assert list(bank.root.glob(".staging-victim-*"))  # it really was mid-write
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    reopened = Bank(bank.root)
    assert reopened.names() == ["before"] and not reopened.problems
    add(reopened, "after", speed=44, extra="param a2 = Range(2, 3)\n")  # a later writer cleans up
    assert not list(bank.root.glob(".staging-*"))
    assert Bank(bank.root).names() == ["after", "before"]


def _parallel_writer(root: str, worker: int, count: int) -> None:
    import scenario_bank.admission as admission

    # the locking and atomic writes are under test, not the check of each script: no jail start per entry
    admission.verify = lambda script, label: None
    bank = Bank(root)
    for k in range(count):
        text = script(worker * 100 + k, f"param w{worker}_{k} = Range({worker}, {k + worker + 1})\n")
        bank.add(text, Sidecar(description=f"worker {worker} entry {k}", name=f"w{worker}_{k}", elements=ELEMENTS))


@pytest.mark.slow
def test_parallel_writers_never_lose_or_corrupt_entries(bank):
    bank.root.mkdir(parents=True)
    ctx = mp.get_context("spawn")
    workers = [ctx.Process(target=_parallel_writer, args=(str(bank.root), w, 8)) for w in range(4)]
    for p in workers:
        p.start()
    for p in workers:
        p.join(600)
        assert p.exitcode == 0, f"writer exit code {p.exitcode} (None: still running after 600 s)"
    reopened = Bank(bank.root)
    assert len(reopened) == 32 and not reopened.problems
    index = json.loads(index_path(reopened).read_text())
    assert sorted(index["entries"]) == reopened.names()
    for entry in reopened:
        assert entry.content_hash == content_hash(entry.script)


_LOCKER = """
import sys
sys.path.insert(0, {root!r})
from scenario_bank.bank import Bank
bank = Bank({bank!r})
print("trying", flush=True)
with bank._lock():
    print("got", flush=True)
"""


def test_writers_with_different_cache_directories_take_the_same_lock(bank, tmp_path, monkeypatch):
    """Two users (or hosts) writing one bank: the lock is the bank's, not the writer's cache's."""
    import select

    add(bank, "first")
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache-a"))
    env = {**os.environ, CACHE_ENV: str(tmp_path / "cache-b")}
    with Bank(bank.root)._lock():
        other = subprocess.Popen([sys.executable, "-c", _LOCKER.format(root=str(ROOT), bank=str(bank.root))],
                                 stdout=subprocess.PIPE, text=True, env=env)
        try:
            assert other.stdout.readline().strip() == "trying"
            ready, _, _ = select.select([other.stdout], [], [], 2.0)
            assert not ready, "a writer with another cache directory took the lock we hold"
        except BaseException:
            other.kill()
            raise
    assert other.stdout.readline().strip() == "got"
    assert other.wait(60) == 0
    assert (bank.root / WRITERS_LOCK).is_file() and Bank(bank.root).names() == ["first"]


def test_stale_index_is_rebuilt_from_sidecars(bank):
    add(bank, "one")
    index_path(bank).write_text("garbage")
    assert Bank(bank.root).names() == ["one"]
    assert json.loads(index_path(bank).read_text())["version"] == BANK_VERSION


def test_the_shipped_bank_is_read_only(tmp_path):
    from scenario_bank.bank import Bank, BankError

    shipped = Bank()
    before = sorted(p.name for p in shipped.root.iterdir())
    with pytest.raises(BankError, match="shipped bank .* read-only.*--bank DIR"):
        shipped.add("param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n", "x")
    with pytest.raises(BankError, match="read-only"):
        shipped.remove(shipped.list()[0].name)
    assert sorted(p.name for p in shipped.root.iterdir()) == before
