"""The conversion record: what became of one converted failure, a line of a mining run's ``conversions.jsonl``.

:func:`~dv2s_gym.mining.conversion.convert.convert_failure` returns a :class:`ConversionRecord`, the miner appends
its :meth:`~scenario_bank.records.JsonRecord.to_dict` to ``conversions.jsonl`` and reads the file back with
:func:`read_conversions` (the report with :meth:`ConversionRecord.from_dict` on the rows it read). Its ``status``
is a :class:`ConversionStatus`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar, Dict, FrozenSet, List, Mapping, Optional, Tuple

from dv2s_gym.mining.jsonl import read_rows
from scenario_bank.records import JsonRecord, RecordError

__all__ = ["ConversionStatus", "ConversionRecord", "read_conversions", "ALWAYS_WRITTEN", "ReplayRow",
           "REPLAY_ALWAYS_WRITTEN", "read_replays", "ConversionOutcome", "read_conversion_outcome"]


class ConversionStatus(StrEnum):
    """What became of a converted script: ``kept`` (a new bank entry), ``merged`` (into the entry it nearly
    duplicates) or ``rejected`` (by a stage or the judge). Each equals its JSON text (``"kept"``, ...)."""

    KEPT = "kept"
    MERGED = "merged"
    REJECTED = "rejected"


ALWAYS_WRITTEN = ("cluster", "index", "status", "reason", "stage", "video", "description", "script", "reproduction",
                  "e2e_sc", "bank_entry", "merged_into", "seconds", "timings", "interaction", "replay_entry",
                  "avoidability", "rejections", "actors", "parameters", "converted_video")
"""The fields every conversion writes, ``null`` when it has none."""


@dataclass(frozen=True, eq=False)
class ConversionRecord(JsonRecord):
    """One conversion of a failure (a line of ``conversions.jsonl``; the fields are described at
    :func:`~dv2s_gym.mining.conversion.convert.convert_failure`): the ``cluster`` and episode ``index`` converted, the
    ``status`` (:class:`ConversionStatus`) with the rejection's ``reason``, ``stage`` and every failed check
    (``rejections``), the failure ``video``, the generated ``description`` and ``script`` (paths relative to the run
    folder), the ``reproduction`` check and its ``e2e_sc``, the ``bank_entry`` kept or the entry it was
    ``merged_into`` (and ``merge_reason``), the exact ``replay_entry`` and the parameters it could not narrow
    (``replay_not_narrowed``), the seconds it took (``seconds``, per stage in ``timings``), the failure's
    ``interaction``, the reference driver's outcome (``avoidability``), the judge's ``actors`` and ``parameters``
    comparisons, the ``converted_video`` clip, and ``recovered_from_bank`` for a record rebuilt from a bank entry's
    provenance. Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default :data:`ALWAYS_WRITTEN`.
    """

    cluster: Optional[str] = None
    index: Optional[int] = None
    status: Optional[ConversionStatus] = None
    reason: Optional[str] = None
    stage: Optional[str] = None
    video: Optional[str] = None
    description: Optional[str] = None
    script: Optional[str] = None
    reproduction: Optional[Mapping[str, Any]] = None
    e2e_sc: Optional[float] = None
    bank_entry: Optional[str] = None
    merged_into: Optional[str] = None
    merge_reason: Optional[str] = None
    seconds: Optional[float] = None
    timings: Optional[Mapping[str, Any]] = None
    interaction: Optional[Mapping[str, Any]] = None
    replay_entry: Optional[str] = None
    replay_not_narrowed: Optional[Mapping[str, Any]] = None
    avoidability: Optional[Mapping[str, Any]] = None
    rejections: Optional[Tuple[str, ...]] = None
    actors: Optional[Mapping[str, Any]] = None
    parameters: Optional[Mapping[str, Any]] = None
    converted_video: Optional[str] = None
    recovered_from_bank: Optional[bool] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "conversion record"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(ALWAYS_WRITTEN)

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return _status(data, cls._WHAT)

    def to_dict(self) -> Dict[str, Any]:
        return _status_written(super().to_dict())

    @property
    def kept(self) -> bool:
        """Whether the converted script became a new bank entry."""
        return self.status == ConversionStatus.KEPT

    @property
    def merged(self) -> bool:
        """Whether the converted script was merged into the bank entry it nearly duplicates."""
        return self.status == ConversionStatus.MERGED

    @property
    def rejected(self) -> bool:
        """Whether the converted script was rejected."""
        return self.status == ConversionStatus.REJECTED


def _status(data: Mapping[str, Any], what: str) -> Dict[str, Any]:
    """The ``status`` of a record's JSON object ``data`` as a :class:`ConversionStatus` (none when absent or
    ``null``); another word is a :class:`~scenario_bank.records.RecordError` naming the ones it can be."""
    if "status" not in data or data["status"] is None:
        return {}
    try:
        return {"status": ConversionStatus(data["status"])}
    except ValueError:
        raise RecordError(f"{what} field 'status' must be one of "
                          f"{', '.join(repr(s.value) for s in ConversionStatus)}, not {data['status']!r}") from None


def _status_written(out: Dict[str, Any]) -> Dict[str, Any]:
    if isinstance(out.get("status"), ConversionStatus):
        out["status"] = out["status"].value
    return out


def read_conversions(path: Path) -> List[ConversionRecord]:
    """The conversion records of a ``conversions.jsonl`` (none when it does not exist; a torn last line, left by a
    kill mid-write, is left out: its conversion runs again); a line that is no conversion record is a
    :class:`~scenario_bank.records.RecordError` naming the file, the line and its bad field."""
    records = []
    for number, row in enumerate(read_rows(path), 1):
        try:
            records.append(ConversionRecord.from_dict(row))
        except RecordError as error:
            raise RecordError(f"{path}, record {number}: {error}; remove that line (its cluster is converted "
                              "again on resume)") from None
    return records


REPLAY_ALWAYS_WRITTEN = ("cluster", "index", "scenario", "status", "replay_entry", "reason", "note", "seconds")
"""The fields every exact replay's row writes, ``null`` when it has none."""


@dataclass(frozen=True, eq=False)
class ReplayRow(JsonRecord):
    """The exact replay of one failure cluster kept without a conversion: a line of a mining run's
    ``replays.jsonl``, what :func:`~dv2s_gym.mining.conversion.replay.replay_failure_entry` returns. The ``cluster``,
    the failing episode's ``index`` and ``scenario`` (the replay's parent), the ``status`` (:class:`ConversionStatus`:
    ``kept`` or ``rejected``), the ``replay_entry`` kept (``None`` with a ``note`` when the bank holds the scene
    already under another name), the rejection's ``reason``, the ``seconds`` it took and, when kept, the parameters
    the replay leaves at the parent's distribution (``replay_not_narrowed``: ``{parameter: why}``). Other keys are
    kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default :data:`REPLAY_ALWAYS_WRITTEN`.
    """

    cluster: Optional[str] = None
    index: Optional[int] = None
    scenario: Optional[str] = None
    status: Optional[ConversionStatus] = None
    replay_entry: Optional[str] = None
    reason: Optional[str] = None
    note: Optional[str] = None
    seconds: Optional[float] = None
    replay_not_narrowed: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "exact replay row"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(REPLAY_ALWAYS_WRITTEN)

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return _status(data, cls._WHAT)

    def to_dict(self) -> Dict[str, Any]:
        return _status_written(super().to_dict())

    @property
    def kept(self) -> bool:
        """Whether the exact replay was kept (with an entry, or with a ``note`` naming the bank's twin)."""
        return self.status == ConversionStatus.KEPT


def read_replays(path: Path) -> List[ReplayRow]:
    """The rows of a ``replays.jsonl`` (none when it does not exist; a torn last line, left by a kill mid-write, is
    left out: its cluster is replayed again); a line that is no replay row is a
    :class:`~scenario_bank.records.RecordError` naming the file, the line and its bad field."""
    rows = []
    for number, row in enumerate(read_rows(path), 1):
        try:
            rows.append(ReplayRow.from_dict(row))
        except RecordError as error:
            raise RecordError(f"{path}, record {number}: {error}; remove that line (its cluster is replayed again "
                              "on resume)") from None
    return rows


@dataclass(frozen=True, eq=False)
class ConversionOutcome(JsonRecord):
    """A conversion's ``report.json`` (``failures/<cluster slug>/conversion/report.json`` of a mining run): the
    conversion record's fields (:class:`ConversionRecord`) with what each stage recorded beside them. Typed here are
    the fields the loop's report reads: the ``status`` (:class:`ConversionStatus`), every failed check
    (``rejections``), the ``reproduction`` check (with its ``clip``) and the ``policy`` the clip shows when the
    file names one; the rest of the file is kept in ``extra``. Absent keys stay absent."""

    status: Optional[ConversionStatus] = None
    rejections: Optional[Tuple[str, ...]] = None
    reproduction: Optional[Mapping[str, Any]] = None
    policy: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "conversion report"

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return _status(data, cls._WHAT)

    def to_dict(self) -> Dict[str, Any]:
        return _status_written(super().to_dict())

    @property
    def merged(self) -> bool:
        """Whether the converted script was merged into the bank entry it nearly duplicates."""
        return self.status == ConversionStatus.MERGED


def read_conversion_outcome(path: Path) -> ConversionOutcome:
    """The :class:`ConversionOutcome` of a conversion's ``report.json`` at ``path``. Raises ``OSError`` when it
    cannot be read, ``ValueError`` when it is no JSON, and :class:`~scenario_bank.records.RecordError` (a
    ``ValueError``) when it is no conversion report (naming the file and the bad field)."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    try:
        return ConversionOutcome.from_dict(data)
    except RecordError as error:
        raise RecordError(f"{path}: {error}") from None
