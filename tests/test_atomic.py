"""The one atomic-write helper: whole new content or the old file, never a partial one."""

from __future__ import annotations

import errno

import numpy as np
import pytest

from disk_helpers import fill_disk_after
from scenario_bank.atomic import (AtomicWriteError, atomic_path, atomic_write_bytes, atomic_write_json,
                                     atomic_write_text, staged_folder)


def test_full_disk_mid_write_leaves_the_old_file_and_no_partial_one(tmp_path, monkeypatch):
    target = tmp_path / "index.json"
    atomic_write_json(target, {"old": True})
    old = target.read_bytes()
    fill_disk_after(monkeypatch, allowed=1000)
    with pytest.raises(AtomicWriteError) as caught:
        atomic_write_bytes(target, b"x" * 100_000, fsync=False)
    assert caught.value.errno == errno.ENOSPC
    assert "disk is full" in str(caught.value) and str(target) in str(caught.value)
    assert target.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.json"]  # no temporary file left


def test_a_new_file_is_absent_after_a_failed_write(tmp_path, monkeypatch):
    target = tmp_path / "sub" / "new.bin"
    fill_disk_after(monkeypatch, allowed=10)
    with pytest.raises(AtomicWriteError):
        atomic_write_bytes(target, b"y" * 5000, fsync=False)
    assert not target.exists() and list(target.parent.iterdir()) == []


def test_atomic_path_renames_on_success_and_drops_on_error(tmp_path):
    target = tmp_path / "clip.webm"
    with atomic_path(target, keep_suffix=True) as tmp:
        assert tmp.suffix == ".webm" and tmp.parent == tmp_path and tmp != target
        tmp.write_bytes(b"video")
    assert target.read_bytes() == b"video"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("encoder crashed")
    assert target.read_bytes() == b"video" and sorted(p.name for p in tmp_path.iterdir()) == ["clip.webm"]


def test_trace_and_video_writers_use_it(tmp_path, monkeypatch):
    """A full disk while saving a trace leaves no file; an abandoned video leaves no file."""
    from envs.recording import VideoWriter
    from envs.trace import EpisodeTrace

    trace = EpisodeTrace(scenario="s", source="x", seed=0, scene_seed=0, params={}, config={},
                         states=[{"ego": [0.0] * 4}] * 2000)
    fill_disk_after(monkeypatch, allowed=100)
    with pytest.raises(AtomicWriteError, match="disk is full"):
        trace.save(tmp_path / "t.json")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(KeyError):
        with VideoWriter(tmp_path / "v.webm") as video:
            video.write(np.zeros((48, 64, 3), np.uint8))
            raise KeyError("episode crashed")
    assert list(tmp_path.iterdir()) == []
    with VideoWriter(tmp_path / "v.webm") as video:
        video.write(np.zeros((48, 64, 3), np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["v.webm"]


def _files(folder):
    return {p.relative_to(folder).as_posix(): p.read_text() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_staged_folder_replaces_its_files_together_and_drops_the_ones_not_written(tmp_path):
    out = tmp_path / "gen"
    out.mkdir()
    for name, text in [("a.txt", "old a"), ("b.txt", "old b"), ("mine.txt", "the user's")]:
        (out / name).write_text(text)
    with staged_folder(out, ("a.txt", "b.txt", "c.txt")) as stage:
        assert stage.parent == tmp_path and not (out / "c.txt").exists()
        atomic_write_text(stage / "a.txt", "new a")
        atomic_write_text(stage / "c.txt", "new c")
        assert _files(out)["a.txt"] == "old a"  # nothing moves before the block ends
    assert _files(out) == {"a.txt": "new a", "c.txt": "new c", "mine.txt": "the user's"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen"]


def test_a_full_disk_in_a_staged_folder_leaves_the_earlier_files_and_no_temporary_one(tmp_path, monkeypatch):
    out = tmp_path / "gen"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    (out / "b.txt").write_text("old b")
    fill_disk_after(monkeypatch, allowed=100)
    with pytest.raises(AtomicWriteError) as caught:
        with staged_folder(out, ("a.txt", "b.txt")) as stage:
            atomic_write_text(stage / "a.txt", "short", fsync=False)
            atomic_write_text(stage / "b.txt", "x" * 5000, fsync=False)
    assert caught.value.errno == errno.ENOSPC
    assert "disk is full" in str(caught.value) and str(out) in str(caught.value) and ".tmp" not in str(caught.value)
    assert _files(out) == {"a.txt": "old a", "b.txt": "old b"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen"]


def test_a_full_disk_in_a_new_staged_folder_leaves_no_folder(tmp_path, monkeypatch):
    fill_disk_after(monkeypatch, allowed=10)
    with pytest.raises(AtomicWriteError):
        with staged_folder(tmp_path / "new" / "gen", ("a.txt",)) as stage:
            atomic_write_text(stage / "a.txt", "x" * 5000, fsync=False)
    assert list(tmp_path.iterdir()) == []


def test_an_error_in_a_staged_folder_that_is_no_write_error_passes_unchanged(tmp_path):
    with pytest.raises(KeyError):
        with staged_folder(tmp_path / "gen", ("a.txt",)) as stage:
            atomic_write_text(stage / "a.txt", "a")
            raise KeyError("boom")
    assert list(tmp_path.iterdir()) == []
