"""The mining run's append-only JSON-lines files: rows appended so that a kill leaves at most a torn last line
(:class:`JsonlAppender`), and read back after a possible kill (:func:`read_rows`)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, List

from scenario_bank.errors import WrongTypeError
from scenario_bank.records import JsonRecord

__all__ = ["JsonlAppender", "read_rows"]


class JsonlAppender:
    """Appends JSON lines to a file, each flushed and fsynced before it counts as written (a torn last line, left
    by a kill mid-write, is dropped when the file is opened again)."""

    def __init__(self, path: Path) -> None:
        self._path = path
        if path.is_file() and path.stat().st_size:
            with open(path, "rb+") as handle:  # drop a torn last line so the next record starts clean
                data = handle.read()
                if not data.endswith(b"\n"):
                    handle.truncate(data.rfind(b"\n") + 1)
        self._handle = open(path, "ab")

    def append(self, record: JsonRecord) -> None:
        """Write ``record`` (a typed record: :class:`~scenario_bank.records.JsonRecord`) as one line, its
        :meth:`~scenario_bank.records.JsonRecord.to_dict` with sorted keys."""
        if not isinstance(record, JsonRecord):
            raise WrongTypeError(f"{self._path.name} holds typed records, not {type(record).__name__}: read a JSON "
                                 "object into its record (the record class's from_dict) before appending it")
        try:
            self._handle.write(json.dumps(record.to_dict(), sort_keys=True, default=str).encode("utf-8") + b"\n")
            self._handle.flush()
            os.fsync(self._handle.fileno())
        except OSError as error:  # a full disk...: name the file (a torn line is dropped when it is opened again)
            raise OSError(error.errno, error.strerror, str(self._path)) from None

    def close(self) -> None:
        try:
            self._handle.close()
        except OSError:
            pass  # the unwritten rest of a line whose append already failed (and was reported)


def read_rows(path: Path) -> List[Dict[str, Any]]:
    """The JSON objects of ``path``, one a line; none when it does not exist. A line that does not parse (the
    torn last line of a run killed mid-write) is left out: its work runs again."""
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            continue
    return rows
