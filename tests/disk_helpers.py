"""A disk that fills up mid-write, for the tests of what a full disk leaves behind."""

from __future__ import annotations

import builtins
import errno

import scenario_bank.atomic as atomic

__all__ = ["fill_disk_after"]


class _FillingFile:
    """A file handle whose writes stop with ENOSPC once the file holds ``allowed`` bytes."""

    def __init__(self, handle, allowed: int):
        self.handle, self.allowed = handle, allowed

    def write(self, data):
        room = max(0, self.allowed - self.handle.tell())
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


def fill_disk_after(monkeypatch, allowed: int) -> None:
    """Make every atomic write (:mod:`scenario_bank.atomic`) fail with ENOSPC once ``allowed`` bytes reached its
    file: a disk filling mid-write."""
    monkeypatch.setattr(atomic, "open", lambda *a, **k: _FillingFile(builtins.open(*a, **k), allowed), raising=False)
