"""Atomic file writes: a file is either its old content, its whole new content, or absent.

The one helper every writer of dv2s-gym uses (bank index and sidecars, episode
traces, videos, generated scenario folders). The data goes to a hidden
temporary file beside the target, is flushed to disk, then renamed over the
target in one step. Any failure (a full disk mid-write included) removes the
temporary file and leaves the target untouched.

This module imports nothing else of dv2s-gym.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator, List, Union

from scenario_bank.errors import DV2SError

__all__ = ["AtomicWriteError", "atomic_write_bytes", "atomic_write_text", "atomic_write_json", "atomic_path",
           "staged_folder", "file_sha256"]

PathLike = Union[str, os.PathLike]


class AtomicWriteError(DV2SError, OSError):
    """A file could not be written; the target is unchanged and no partial file is left."""


def _error(error: OSError, path: Path) -> AtomicWriteError:
    if error.errno == errno.ENOSPC:
        message = f"the disk is full while writing {path}; free some space and retry ({path.name} is unchanged)"
    elif error.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        message = f"no permission to write {path}; choose a writable location ({path.name} is unchanged)"
    else:
        message = f"could not write {path}: {error.strerror or error} ({path.name} is unchanged)"
    wrapped = AtomicWriteError(error.errno, message)
    wrapped.filename = str(path)
    return wrapped


def _temp_name(path: Path, suffix: str = "") -> Path:
    return path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp{suffix}")


@contextmanager
def atomic_path(path: PathLike, *, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path to write to; on success it is renamed onto ``path``.

    For writers that need a file name rather than a handle (e.g. OpenCV's video
    writer). ``keep_suffix`` ends the temporary name in ``path``'s suffix, for
    writers that pick a format from it. If the block raises, or the temporary
    file was not created, the target is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_name(path, path.suffix if keep_suffix else "")
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(errno.ENOENT, f"nothing was written to the temporary file for {path}")
        os.replace(tmp, path)
    except OSError as error:
        if isinstance(error, AtomicWriteError):
            raise
        raise _error(error, path) from None
    finally:
        tmp.unlink(missing_ok=True)


def _missing_folders(folder: Path) -> List[Path]:
    """The folders of ``folder``'s path that do not exist yet, deepest first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


@contextmanager
def staged_folder(folder: PathLike, names: Iterable[str]) -> Iterator[Path]:
    """Yield a hidden temporary folder beside ``folder`` to write a set of files in; on success each of ``names``
    written there replaces its namesake in ``folder`` and each not written is removed from it (a file of an earlier
    run that this one did not make is not left to pass as its result); other files in ``folder`` stay.

    If the block raises (a full disk mid-write included), ``folder`` is left exactly as it was (a folder this call
    had to create is removed again) and the temporary folder is removed; an ``OSError`` comes out as an
    :class:`AtomicWriteError` naming ``folder``, the problem and the fix.
    """
    folder = Path(folder)
    created = _missing_folders(folder)
    stage = _temp_name(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        stage.mkdir()
        yield stage
        for name in names:
            if (stage / name).is_file():
                os.replace(stage / name, folder / name)
            else:
                (folder / name).unlink(missing_ok=True)
    except BaseException as error:
        shutil.rmtree(stage, ignore_errors=True)
        for made in created:  # deepest first: each is empty once the one below it is gone
            if made.is_dir() and not any(made.iterdir()):
                made.rmdir()
        if isinstance(error, OSError):  # named by the folder, not the temporary one the file was written in
            raise _error(error, folder) from None
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def atomic_write_bytes(path: PathLike, data: bytes, *, fsync: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path.

    Raises:
        AtomicWriteError: (an ``OSError``) the write failed, e.g. the disk is
            full; the message names the file and the fix, and nothing partial is left.
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            if fsync:
                os.fsync(handle.fileno())
    return path


def atomic_write_text(path: PathLike, text: str, *, encoding: str = "utf-8", fsync: bool = True) -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode(encoding), fsync=fsync)


def atomic_write_json(path: PathLike, data: Any, *, indent: int = 1, fsync: bool = True) -> Path:
    """Write ``data`` as JSON (sorted keys) to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_text(path, json.dumps(data, indent=indent, sort_keys=True) + "\n", fsync=fsync)


def file_sha256(path: Union[str, os.PathLike]) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
