"""Hostile bank archives and folders (``tests/hostile/bank/``) through the Bank API and the ``dv2s bank`` CLI.

Each one is refused with one clear error naming the problem (exit 2 for the commands it stops; ``bank list``
names the broken entry on a ``!`` line and keeps listing the others, ``bank validate`` reports it as FAIL),
nothing is written outside the temporary bank nor into it, no secret outside the bank is printed or
exported, and nothing hangs: the CLI runs in a subprocess with a timeout.
"""

import io
import json
import os
import shutil
import stat
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from scenario_bank.bank import BANK_DIR, WRITERS_LOCK, Bank, BankError, Sidecar, UnknownScenarioError
from scenario_bank.safe_files import (UnsafeInputError, load_json_bounded, read_in_folder, read_regular_file,
                                      validate_entry_name, validate_relative_path)

HOSTILE = Path(__file__).parent / "hostile" / "bank"
sys.path.insert(0, str(HOSTILE))
from folders import FOLDERS, SECRET  # noqa: E402
from make_archives import ARCHIVES, ESCAPE  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GOOD = "highway_cut_in_from_left"
TIMEOUT = 120  # seconds; a hang fails the test instead of stalling the run


def cli(*argv):
    """``(exit code, stdout, stderr)`` of ``dv2s ARGV`` in a subprocess that must end within TIMEOUT."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *map(str, argv)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=TIMEOUT, errors="replace")
    return done.returncode, done.stdout, done.stderr


def snapshot(top: Path):
    """Every path under ``top`` (links not followed) with its type and, for regular files, its bytes."""
    out = {}
    for folder, dirs, files in os.walk(top):
        for name in dirs + files:
            path = Path(folder) / name
            if name == WRITERS_LOCK:
                continue
            mode = os.lstat(path).st_mode
            out[str(path.relative_to(top))] = (stat.S_IFMT(mode), path.read_bytes() if stat.S_ISREG(mode) else None)
    return out


@pytest.fixture
def world(tmp_path):
    """``(bank, secret, outside)``: a bank holding one good entry, a secret file and a folder outside it."""
    bank = tmp_path / "bank"
    shutil.copytree(BANK_DIR / GOOD, bank / GOOD)
    outside = tmp_path / "outside"
    outside.mkdir()
    secret = outside / "secret.txt"
    secret.write_text(f"# {SECRET}\n")
    return bank, secret, outside


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dv2s: error: ") and "Traceback" not in err, err
    assert "unexpected error" not in err, err
    return lines[0]


def test_the_corpus_is_complete():
    assert len(ARCHIVES) + len(FOLDERS) >= 30
    for name in ARCHIVES:
        assert (HOSTILE / name).is_file() and (HOSTILE / name).stat().st_size < 400_000, name


# ------------------------------------------------------------------ archives
# the two archives that take over a second of CPU to refuse (measured) run with the slow tests
_SLOW_ARCHIVES = {"many_members.tar.gz", "total_size_bomb.tar.gz"}


@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow) if name in _SLOW_ARCHIVES else name
                                  for name in sorted(ARCHIVES)])
def test_hostile_archive_is_refused_by_the_api(name, world, tmp_path):
    bank_dir, _, _ = world
    expected = ARCHIVES[name][0]
    before = snapshot(tmp_path)
    with pytest.raises(BankError) as error:
        Bank(bank_dir).import_archive(HOSTILE / name)
    assert expected in str(error.value) and "nothing was imported" in str(error.value)
    assert snapshot(tmp_path) == before
    assert not os.path.lexists(ESCAPE)
    assert Bank(bank_dir).names() == [GOOD]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ARCHIVES))
def test_hostile_archive_is_refused_by_the_cli(name, world, tmp_path):
    bank_dir, _, _ = world
    before = snapshot(tmp_path)
    code, out, err = cli("bank", "--bank", bank_dir, "import", HOSTILE / name)
    assert code == 2 and ARCHIVES[name][0] in one_error_line(err), err
    assert snapshot(tmp_path) == before and not os.path.lexists(ESCAPE)


def test_import_into_a_new_bank_leaves_no_folder_behind(tmp_path):
    code, _, err = cli("bank", "--bank", tmp_path / "new", "import", HOSTILE / "absolute_member.tar.gz")
    assert code == 2 and "invalid member name" in err
    assert not (tmp_path / "new").exists()  # not even a folder holding only the writers' lock
    (tmp_path / "existing").mkdir()
    code, _, err = cli("bank", "--bank", tmp_path / "existing", "import", HOSTILE / "absolute_member.tar.gz")
    assert code == 2 and (tmp_path / "existing").is_dir()  # a folder the user made stays


def test_a_fifo_given_as_the_archive_is_refused_without_waiting(world, tmp_path):
    bank_dir, _, _ = world
    os.mkfifo(tmp_path / "archive.tar.gz")
    code, _, err = cli("bank", "--bank", bank_dir, "import", tmp_path / "archive.tar.gz")
    assert code == 2 and "FIFO" in one_error_line(err)


def test_truncated_and_corrupt_archives_are_one_clear_error(world, tmp_path):
    bank_dir, _, _ = world
    data = (HOSTILE / "meta_files_outside.tar.gz").read_bytes()
    (tmp_path / "cut.tar.gz").write_bytes(data[: len(data) // 2])
    (tmp_path / "noise.tar.gz").write_bytes(b"\x1f\x8b" + os.urandom(200))
    for archive in ("cut.tar.gz", "noise.tar.gz"):
        with pytest.raises(BankError, match="not a readable bank archive"):
            Bank(bank_dir).import_archive(tmp_path / archive)
    assert Bank(bank_dir).names() == [GOOD]


def test_an_exported_archive_still_imports(world, tmp_path):
    bank_dir, _, _ = world
    archive = Bank(bank_dir).export(tmp_path / "out.tar.gz")
    with tarfile.open(archive) as tar:
        assert sorted(m.name for m in tar) == ["bank-archive.json", f"{GOOD}/meta.json", f"{GOOD}/scenario.scenic"]
    target = tmp_path / "other"
    shutil.copytree(bank_dir, target)
    assert Bank(target).import_archive(archive) == {"added": [], "skipped": [GOOD]}  # a duplicate: no sandbox run


# ------------------------------------------------------------------- folders
def plant(name, world):
    bank_dir, secret, outside = world
    FOLDERS[name][0](bank_dir, secret, outside)
    broken = Bank(bank_dir)
    keys = [k for k in list(broken.problems) + broken.names() if k != GOOD]
    assert len(keys) == 1, (broken.names(), broken.problems)
    return keys[0]


@pytest.mark.parametrize("name", sorted(FOLDERS))
def test_hostile_folder_through_the_api(name, world, tmp_path):
    bank_dir, secret, outside = world
    key = plant(name, world)
    expected = FOLDERS[name][1]
    before = snapshot(tmp_path)
    bank = Bank(bank_dir)
    assert GOOD in bank.names() and bank.get(GOOD).script
    if expected is None:  # usable, but the linked file is never read: it counts as missing
        entry = bank.get(key)
        assert entry.missing_files() == ["failure.webm"]
        archive = bank.export(tmp_path / "export.tar.gz")
        with tarfile.open(archive) as tar:
            assert f"{key}/failure.webm" not in tar.getnames()
        copy = bank.copy_to(tmp_path / "copy")
        assert not (copy.root / key / "failure.webm").exists()
        (tmp_path / "export.tar.gz").unlink()
        shutil.rmtree(tmp_path / "copy")
    else:
        assert key not in bank.names() and expected in bank.problems[key]
        with pytest.raises(UnknownScenarioError, match="unusable"):
            bank.get(key)
        assert bank.sample(0).name == GOOD
        archive = bank.export(tmp_path / "export.tar.gz")  # the broken entry is left out
        with tarfile.open(archive) as tar:
            assert all(m.startswith((GOOD, "bank-archive")) for m in tar.getnames())
        (tmp_path / "export.tar.gz").unlink()
    assert snapshot(tmp_path) == before


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FOLDERS))
def test_hostile_folder_through_the_cli(name, world, tmp_path):
    bank_dir, secret, outside = world
    key = plant(name, world)
    expected = FOLDERS[name][1]
    before = snapshot(tmp_path)

    code, out, err = cli("bank", "--bank", bank_dir, "list")
    assert code == 0 and SECRET not in out + err, err
    assert any(line.startswith(GOOD) for line in out.splitlines())
    assert not any(line.startswith("! good") for line in out.splitlines())  # no line forged by a folder name
    if expected is not None:
        assert f"! {key}: " in out and expected in out

    code, out, err = cli("bank", "--bank", bank_dir, "show", key)
    assert SECRET not in out + err
    if expected is None:
        assert code == 0 and "failure.webm (missing)" in out
    else:
        assert code == 2 and expected in one_error_line(err)

        code, out, err = cli("bank", "--bank", bank_dir, "validate", key)
        assert code == 1 and out.startswith(f"FAIL {key}") and expected in out and SECRET not in out + err, err

        alone, elsewhere = tmp_path / "alone", tmp_path / "elsewhere"  # a bank holding only the hostile entry
        alone.mkdir()
        elsewhere.mkdir()
        FOLDERS[name][0](alone, secret, elsewhere)
        code, out, err = cli("bank", "--bank", alone, "sample")
        assert code == 2 and "no scenarios to sample" in one_error_line(err) and expected in err
        shutil.rmtree(alone)
        shutil.rmtree(elsewhere)

    code, out, err = cli("bank", "--bank", bank_dir, "sample", "--count", "3", "--json")
    assert code == 0 and (json.loads(out) == [GOOD] * 3 or expected is None)
    assert snapshot(tmp_path) == before


@pytest.mark.slow
def test_names_given_on_the_command_line_are_validated(world):
    bank_dir, _, _ = world
    for command, said in ((["show", "../outside"], "`dv2s bank show` takes the name of a scenario in the bank"),
                          (["validate", "/etc"], "invalid scenario name"),
                          (["rm", "../x"], "`dv2s bank rm` takes the name of a scenario in the bank"),
                          (["export", "a.tar.gz", "--name", "a/b"], "invalid scenario name")):
        code, _, err = cli("bank", "--bank", bank_dir, *command)
        assert code == 2 and said in one_error_line(err), (command, err)
    assert Bank(bank_dir).names() == [GOOD]


def test_weights_and_elements_given_on_the_command_line_are_bounded(world, tmp_path):
    bank_dir, _, _ = world
    code, _, err = cli("bank", "--bank", bank_dir, "sample", "--weights", "[" * 5000 + "]" * 5000)
    assert code == 2 and "deeper than" in one_error_line(err)
    fifo = tmp_path / "script.scenic"
    os.mkfifo(fifo)
    code, _, err = cli("bank", "--bank", bank_dir, "add", fifo, "--description", "d")
    assert code == 2 and "FIFO" in one_error_line(err)


# ------------------------------------------------------------ the helpers
def test_entry_names_and_paths():
    for bad in ("", ".", "..", "../x", "/abs", "a/b", "a\x00b", "a\nb", ".hidden", "-rf", "a..b", "x" * 129, None, 3):
        with pytest.raises(UnsafeInputError):
            validate_entry_name(bad)
    for good in ("a", "A_b-c.d", "_x", "9" * 128):
        assert validate_entry_name(good) == good
    assert validate_relative_path("merged/1/failure.webm") == "merged/1/failure.webm"
    for bad in ("/etc/passwd", "a//b", "a/../b", "a/", "/".join("a" * 9), "a/.git"):
        with pytest.raises(UnsafeInputError):
            validate_relative_path(bad)


def test_json_depth_prescan_ignores_brackets_in_strings():
    assert load_json_bounded(b'{"a": "[[[[[[[[\\"]]]", "b": [[1]]}', max_depth=3) == {"a": '[[[[[[[["]]]', "b": [[1]]}
    with pytest.raises(UnsafeInputError, match="deeper than 2"):
        load_json_bounded(b'{"a": [[1]]}', max_depth=2)
    with pytest.raises(UnsafeInputError, match="not valid JSON"):
        load_json_bounded(b'{"a": ', max_depth=2)
    with pytest.raises(UnsafeInputError, match="UTF-8"):
        load_json_bounded(b'"\xff"')


def test_reads_stop_at_the_cap_and_never_follow_links(tmp_path):
    (tmp_path / "f").write_bytes(b"x" * 11)
    assert read_regular_file(tmp_path / "f", 11) == b"x" * 11
    with pytest.raises(UnsafeInputError, match="larger than 10 bytes"):
        read_regular_file(tmp_path / "f", 10)
    (tmp_path / "real").mkdir()
    (tmp_path / "real" / "f").write_text("inside")
    os.symlink(tmp_path / "real", tmp_path / "link")
    with pytest.raises(UnsafeInputError, match="not a folder"):
        read_in_folder(tmp_path, "link/f", 100)
    os.symlink(tmp_path / "f", tmp_path / "real" / "g")
    with pytest.raises(UnsafeInputError, match="symbolic link"):
        read_in_folder(tmp_path, "real/g", 100)
    assert read_regular_file(tmp_path / "real" / "g", 100, follow_symlinks=True) == b"x" * 11
    with pytest.raises(UnsafeInputError, match="a folder"):
        read_regular_file(tmp_path / "real", 100)


def test_an_oversized_archive_stops_at_the_cap_while_streaming(world, tmp_path):
    """The header claims a small size for nothing; the data stream itself is what is counted."""
    bank_dir, _, _ = world
    from scenario_bank.safe_files import ArchiveLimits

    raw = io.BytesIO()
    with tarfile.open(fileobj=raw, mode="w") as tar:
        header = json.dumps({"dv2s_bank_archive": 1, "entries": ["x"]}).encode()
        info = tarfile.TarInfo("bank-archive.json")
        info.size = len(header)
        tar.addfile(info, io.BytesIO(header))
        info = tarfile.TarInfo("x/data.bin")
        info.size = 5000
        tar.addfile(info, io.BytesIO(b"\0" * 5000))
    (tmp_path / "a.tar").write_bytes(raw.getvalue())
    with pytest.raises(BankError, match="limit of its total size"):
        Bank(bank_dir).import_archive(tmp_path / "a.tar", limits=ArchiveLimits(max_total_bytes=4096))
    with pytest.raises(BankError, match="larger than 1000 bytes"):
        Bank(bank_dir).import_archive(tmp_path / "a.tar", limits=ArchiveLimits(max_file_bytes=1000))
    assert Bank(bank_dir).names() == [GOOD]


def test_a_merge_never_writes_through_a_linked_folder(world, tmp_path, monkeypatch):
    """An entry whose ``merged`` folder links outside the bank: the merged failure's files are refused."""
    import scenario_bank.bank as bank_module

    bank_dir, _, outside = world
    monkeypatch.setattr(bank_module, "verify_or_name_scenic2", lambda *args: None)  # no sandbox run needed here
    os.symlink(outside, bank_dir / GOOD / "merged")
    video = tmp_path / "failure.webm"
    video.write_bytes(b"video")
    before = snapshot(tmp_path)
    bank = Bank(bank_dir)
    entry = bank.get(GOOD)
    with pytest.raises(BankError, match="symbolic link"):
        bank.add(entry.script, Sidecar(description="the same failure", elements=entry.elements, map=entry.map,
                                       source={"kind": "mined"}), files={"failure.webm": video}, on_duplicate="merge")
    assert snapshot(tmp_path) == before and list(outside.iterdir()) == [outside / "secret.txt"]


ESCAPES = "\x1b]2;PWNED\x07\x1b[2J\x1b[31mRED"


@pytest.mark.slow
def test_escape_sequences_in_sidecars_are_refused_and_never_printed(world, tmp_path):
    bank_dir, _, _ = world
    evil = tmp_path / "evil" / "evil_entry"
    shutil.copytree(bank_dir / GOOD, evil)
    meta = json.loads((evil / "meta.json").read_text())
    meta.update(name="evil_entry", description="desc " + ESCAPES, tags=meta["tags"] + ["tag" + ESCAPES])
    (evil / "meta.json").write_text(json.dumps(meta))
    archive = tmp_path / "escapes.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        header = json.dumps({"dv2s_bank_archive": 1, "entries": ["evil_entry"]}).encode()
        info = tarfile.TarInfo("bank-archive.json")
        info.size = len(header)
        tar.addfile(info, io.BytesIO(header))
        tar.add(evil, arcname="evil_entry")
    code, _, err = cli("bank", "--bank", bank_dir, "import", archive)
    assert code == 2 and "control character" in one_error_line(err)
    assert Bank(bank_dir).names() == [GOOD]

    with pytest.raises(BankError, match="description holds a control character"):
        Bank(bank_dir).add(Bank().get(GOOD).script, Sidecar(description="brakes " + ESCAPES, name="evil_added"))

    shutil.copytree(evil, bank_dir / "evil_entry")  # a folder edited by hand
    for argv in (("list",), ("show", "evil_entry"), ("show", GOOD)):
        code, out, err = cli("--bank", bank_dir, "bank", *argv)
        assert "\x1b" not in out + err and "\x07" not in out + err, argv
    code, out, _ = cli("--bank", bank_dir, "bank", "list")
    assert code == 0 and "evil_entry" in out and "control character" in out
