"""The conversion record: what became of one converted failure, a line of a mining run's ``conversions.jsonl``.

:func:`~dv2s_gym.mining.conversion.convert.convert_failure` returns a :class:`ConversionRecord`, the miner appends
its :meth:`~scenario_bank.records.JsonRecord.to_dict` to ``conversions.jsonl`` and reads the file back with
:func:`read_conversions` (the report with :meth:`ConversionRecord.from_dict` on the rows it read). Its ``status``
is a :class:`ConversionStatus`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar, Dict, FrozenSet, List, Mapping, Optional, Tuple

from dv2s_gym.mining.jsonl import read_rows
from scenario_bank.records import JsonRecord, RecordError

__all__ = ["ConversionStatus", "ConversionRecord", "read_conversions", "ALWAYS_WRITTEN"]


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
        if "status" not in data or data["status"] is None:
            return {}
        try:
            return {"status": ConversionStatus(data["status"])}
        except ValueError:
            raise RecordError(f"conversion record field 'status' must be one of "
                              f"{', '.join(repr(s.value) for s in ConversionStatus)}, not {data['status']!r}") from None

    def to_dict(self) -> Dict[str, Any]:
        out = super().to_dict()
        if isinstance(out.get("status"), ConversionStatus):
            out["status"] = out["status"].value
        return out

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
