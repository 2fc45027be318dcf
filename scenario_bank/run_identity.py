"""The settings that define a resumable run, and the check that a resumed run is the same run.

Every resumable command (``dv2s train`` and fine-tuning, ``dv2s mine``, ``dv2s loop``, a DAgger fine-tuning)
records the settings that make its result what it is when it starts, and compares them with the settings
of the call that resumes it: a difference is refused with :class:`RunIdentityError`, which names every
setting that differs (the recorded and the asked value) and the fix. Settings that only change how the
run goes (workers, progress bars) are not part of a run's identity.

Each run record also carries its format (:func:`record_format`: a schema name and a version number, bumped when
the record's fields change); a record of any other format, or of none, is refused by :func:`check_format` in one
line saying that another version of dv2s-gym wrote the folder and that a new ``--out`` folder starts the run anew.
A setting a record does not hold, or holds as ``null``, is ``None``.

A run also records what its scenarios *are* (:func:`bank_identity`: each scenario's script SHA-256, under
:data:`BANK_IDENTITY`): a resume over a script edited since the run began is refused by :func:`check_bank_unchanged`,
naming the scenario.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Type, Union

from scenario_bank.dedup import content_hash
from scenario_bank.errors import DV2SError

__all__ = ["RunIdentityError", "identity_of", "differing", "check_identity", "setting", "resume_keys",
           "recorded_settings", "record_format", "check_format", "FORMAT_KEYS", "BANK_IDENTITY", "bank_identity",
           "check_bank_unchanged", "RUN_KINDS", "CONVERSION_KIND", "CONVERSION_KEYS",
           "check_run_kind"]

_SHOWN = 3
"""Differences spelled out in a refusal (the rest are counted)."""
FORMAT_KEYS = ("schema", "version")
"""The keys of a run record that name its format (:func:`record_format`)."""


class RunIdentityError(DV2SError, ValueError):
    """A run folder holds a run made with other settings than the ones asked to resume it.

    ``differences`` lists ``(setting, recorded value, asked value)`` for every setting that differs.
    """

    def __init__(self, message: str, differences: Sequence[tuple] = ()) -> None:
        super().__init__(message)
        self.differences = list(differences)


def identity_of(settings: Mapping[str, Any], keys: Sequence[str]) -> dict:
    """The identity part of ``settings``: the ``keys`` it defines, as JSON-safe values."""
    return json.loads(json.dumps({key: settings.get(key) for key in keys}, default=str))


def _same(recorded: Any, asked: Any) -> bool:
    """Equal as Python values or as JSON (a tuple asked against the list JSON gives back, 1 against 1.0)."""
    if recorded == asked:
        return True
    return json.dumps(recorded, sort_keys=True, default=str) == json.dumps(asked, sort_keys=True, default=str)


def differing(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str]) -> List[str]:
    """The ``keys`` whose values differ between ``recorded`` and ``asked``, in ``keys``' order (a setting one of
    them lacks is ``None``)."""
    return [key for key in keys if not _same(recorded.get(key), asked.get(key))]


def _show(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _difference(recorded: Any, asked: Any) -> str:
    """How an asked setting differs from the recorded one: two lists by what one has and the other lacks (their
    shortened texts may read the same), anything else by both values."""
    if isinstance(recorded, (list, tuple)) and isinstance(asked, (list, tuple)):
        old = [json.dumps(v, sort_keys=True, default=str) for v in recorded]
        new = [json.dumps(v, sort_keys=True, default=str) for v in asked]
        added = [json.loads(v) for v in new if v not in old]
        removed = [json.loads(v) for v in old if v not in new]
        if added or removed:
            parts = ([f"asked adds {_show(added)}"] if added else []) + ([f"leaves out {_show(removed)}"] if removed else [])
            return f"the run has {len(recorded)}, {' and '.join(parts)}"
        return f"the same {len(recorded)} in another order (run has {_show(recorded)}, asked {_show(asked)})"
    return f"run has {_show(recorded)}, asked {_show(asked)}"


def check_identity(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str], *, run: str,
                   fix: str, notes: Optional[Mapping[str, str]] = None,
                   error: Type[RunIdentityError] = RunIdentityError) -> None:
    """Refuse to resume ``run`` (e.g. ``"out/mine holds a mining run"``) when any of ``keys`` differs (a setting
    absent from ``recorded`` or ``asked`` is ``None``: a record of this format holds every setting,
    :func:`check_format`).

    Raises:
        RunIdentityError: ``"<run> with other settings (<key>: run has <old>, asked <new>; ...); <fix>"``;
            ``notes`` adds a parenthesised why to a setting (a derived one, such as a file's hash). ``error``:
            the subclass raised (a command's own, such as ``dv2s regress``'s ``ResumeMismatchError``).
    """
    keys_differing = differing(recorded, asked, keys)
    if not keys_differing:
        return
    differences = [(key, recorded.get(key), asked.get(key)) for key in keys_differing]
    shown = [f"{key}: {_difference(old, new)}{(notes or {}).get(key, '')}" for key, old, new in differences[:_SHOWN]]
    if len(differences) > _SHOWN:
        shown.append(f"and {len(differences) - _SHOWN} more")
    raise error(f"{run} with other settings ({'; '.join(shown)}); {fix}", differences)


def record_format(schema: str, version: int) -> Dict[str, Any]:
    """The keys that open a run record of format ``version`` of ``schema`` (e.g. ``"dv2s-mine"``): ``{"schema":
    schema, "version": version}``; :func:`check_format` refuses any other on resume."""
    return {"schema": schema, "version": version}


def check_format(record: Any, schema: str, version: int, *, folder: Any, what: str, file: str,
                 error: Type[Exception]) -> None:
    """Refuse a run record (``file`` in ``folder``, which holds ``what``, e.g. ``"a mining run"``) that is not of
    format ``version`` of ``schema`` (:func:`record_format`): one written by another version of dv2s-gym, which
    this one does not read on.

    Raises:
        error: ``"<folder> holds <what> written by another version of dv2s-gym (its <file> records format <n> |
            no format, this dv2s-gym reads format <version>); start a new --out folder"``.
    """
    found = record.get("version") if isinstance(record, Mapping) and record.get("schema") == schema else None
    if found == version and type(found) is int:
        return
    written = f"format {found}" if isinstance(found, int) and not isinstance(found, bool) else "no format"
    raise error(f"{folder} holds {what} written by another version of dv2s-gym (its {file} records {written}, "
                f"this dv2s-gym reads format {version}); start a new --out folder")


CONVERSION_KIND = "dv2s-conversion"
"""The :data:`RUN_KINDS` key of a D-V2S conversion folder (``dv2s generate``, ``dv2s convert``): its record is its
``report.json``, known by its shape (:data:`CONVERSION_KEYS`), for it names no schema."""
CONVERSION_KEYS = ("description", "seconds", "files")
"""The keys every conversion's ``report.json`` holds (a JSON object naming no ``schema``)."""

RUN_KINDS = {"dv2s-mine": ("settings.json", "a mining run"), "dv2s-regress-run": ("run.json", "a regression run"),
             "dv2s-train-run": ("run.json", "a training run"), "dv2s-loop-state": ("loop.json", "a loop"),
             CONVERSION_KIND: ("report.json", "a D-V2S conversion")}
"""Every kind of run folder, by the schema of its record: ``{schema: (the record's file, what the folder holds)}``;
the conversion's record names no schema and is known by its keys (:data:`CONVERSION_KEYS`). All of them write
``report.json`` at the top of their folder (the runs ``report.md``/``.html`` too), so no two share one."""


def _holds(record: Any, kind: str) -> bool:
    """Whether ``record`` (a run folder's file, read) is the record of a run of ``kind``."""
    if not isinstance(record, Mapping):
        return False
    if kind == CONVERSION_KIND and "schema" not in record:
        return all(key in record for key in CONVERSION_KEYS) and isinstance(record["description"], Mapping)
    return record.get("schema") == kind


def check_run_kind(folder: Any, schema: str, *, error: Type[Exception]) -> None:
    """Refuse to run a run of ``schema`` (a :data:`RUN_KINDS` key) in ``folder`` when it holds a run of another
    kind (whose reports the new run would write over).

    Raises:
        error: ``"<folder> holds <a mining run> (its settings.json), not <a loop>: pass another --out"``.
    """
    own = RUN_KINDS[schema][1]
    for other, (file, what) in RUN_KINDS.items():
        path = Path(folder) / file
        if other == schema or not path.is_file():
            continue
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # not a record of that kind: its own check, if any, says what is wrong
        if _holds(record, other):
            raise error(f"{folder} holds {what} (its {file}), not {own}: pass another --out (a run writes its "
                        "reports at the top of its folder, over the other run's)")


# --------------------------------------------------------------------------- settings dataclasses
_RESUME = "resume"
_RECORD = "record"
_CASTS = {"float": float, "int": int, "bool": bool}


def setting(default: Any = dataclasses.MISSING, *, default_factory: Any = dataclasses.MISSING, resume: bool = True,
            record: Union[bool, Callable[[Any], Any]] = True) -> Any:
    """A field of a run's settings dataclass, saying how a run treats it (a plain field is part of the run's
    identity and recorded as its JSON value).

    ``resume=False``: a resumed run may ask another value (it is not part of the run's identity, :func:`resume_keys`).
    ``record``: ``False`` when the run folder does not record the setting, or the function giving its recorded value
    (instead of :func:`recorded_settings`' plain JSON form)."""
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={_RESUME: resume, _RECORD: record})


def resume_keys(settings_class: type) -> Tuple[str, ...]:
    """The fields of a settings dataclass a resumed run must share with the run it continues, in field order
    (every field but those declared with ``setting(resume=False)``)."""
    return tuple(f.name for f in dataclasses.fields(settings_class) if f.metadata.get(_RESUME, True))


def recorded_settings(settings: Any) -> Dict[str, Any]:
    """The fields of a settings dataclass as its run folder records them (JSON values), in field order: a tuple as a
    list, a mapping as a dict, a value of a ``float``, ``int`` or ``bool`` field as that type (``1`` as ``1.0``);
    a field declared with ``setting(record=...)`` through its function, or left out with ``record=False``."""
    values: Dict[str, Any] = {}
    for field in dataclasses.fields(settings):
        record = field.metadata.get(_RECORD, True)
        if record is False:
            continue
        value = getattr(settings, field.name)
        values[field.name] = record(value) if callable(record) else _json_value(field, value)
    return values


def _json_value(field: dataclasses.Field, value: Any) -> Any:
    if value is None:
        return None
    cast = _CASTS.get(field.type if isinstance(field.type, str) else getattr(field.type, "__name__", ""))
    if cast is not None:
        return cast(value)
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, Mapping):
        return dict(value)
    return value


# --------------------------------------------------------------------------- the bank's scripts
BANK_IDENTITY = "bank_identity"
"""The key under which a run's record holds :func:`bank_identity` of its scenarios."""


def bank_identity(bank: Any, names: Sequence[str]) -> Dict[str, str]:
    """``{scenario: SHA-256 of its script}`` for ``names`` in ``bank`` (a :class:`~scenario_bank.bank.Bank`), sorted
    by name: the scripts as they are on disk now (the hash ``dv2s bank validate`` compares with an entry's
    ``content_hash``)."""
    return {name: content_hash(bank.get(name).script) for name in sorted(set(names))}


def check_bank_unchanged(recorded: Optional[Mapping[str, Any]], now: Mapping[str, str], *, run: str,
                         error: Type[Exception] = RunIdentityError) -> None:
    """Refuse to resume ``run`` (e.g. ``"out/mine holds a mining run"``) when a scenario's script differs from the
    one ``recorded`` (:func:`bank_identity` when the run began), or a scenario was added or left out.

    Raises:
        error: ``"<run> over other scenario scripts (the bank's script for 'x' changed since the run began); restore
            the script, or start a new --out folder"``.
    """
    recorded = dict(recorded or {})
    changed = sorted(name for name in set(recorded) & set(now) if recorded[name] != now[name])
    gone = sorted(set(recorded) - set(now))
    added = sorted(set(now) - set(recorded))
    if not (changed or gone or added):
        return
    said = [f"the bank's script for {name!r} changed since the run began" for name in changed[:_SHOWN]]
    said += [f"{name!r} was not part of the run" for name in added[:_SHOWN]]
    said += [f"{name!r} is no longer asked" for name in gone[:_SHOWN]]
    restore = "the scripts as the run used them" if len(said) > 1 else "the script as the run used it"
    raise error(f"{run} over other scenario scripts ({'; '.join(said)}); restore {restore}, or start a new --out "
                "folder")
