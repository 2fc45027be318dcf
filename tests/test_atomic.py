"""The one atomic-write helper: whole new content or the old file, never a partial one."""

from __future__ import annotations

import errno

import numpy as np
import pytest

from scenario_bank.atomic import AtomicWriteError, atomic_path, atomic_write_bytes, atomic_write_json


def _fill_disk_after(monkeypatch, allowed: int) -> None:
    """Make the helper's writes fail with ENOSPC after ``allowed`` bytes reached the file (a disk filling mid-write)."""
    import builtins

    import scenario_bank.atomic as atomic

    class FillingFile:
        def __init__(self, handle):
            self.handle = handle

        def write(self, data):
            room = max(0, allowed - self.handle.tell())
            self.handle.write(data[:room])
            self.handle.flush()
            if len(data) > room:
                raise OSError(errno.ENOSPC, "No space left on device")
            return len(data)

        def __getattr__(self, name):
            return getattr(self.handle, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()

    monkeypatch.setattr(atomic, "open", lambda *a, **k: FillingFile(builtins.open(*a, **k)), raising=False)


def test_full_disk_mid_write_leaves_the_old_file_and_no_partial_one(tmp_path, monkeypatch):
    target = tmp_path / "index.json"
    atomic_write_json(target, {"old": True})
    old = target.read_bytes()
    _fill_disk_after(monkeypatch, allowed=1000)
    with pytest.raises(AtomicWriteError) as caught:
        atomic_write_bytes(target, b"x" * 100_000, fsync=False)
    assert caught.value.errno == errno.ENOSPC
    assert "disk is full" in str(caught.value) and str(target) in str(caught.value)
    assert target.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.json"]  # no temporary file left


def test_a_new_file_is_absent_after_a_failed_write(tmp_path, monkeypatch):
    target = tmp_path / "sub" / "new.bin"
    _fill_disk_after(monkeypatch, allowed=10)
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
    _fill_disk_after(monkeypatch, allowed=100)
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
