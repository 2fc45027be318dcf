"""Typed records of what travels between the bank, the miner, the regression runner and the policies.

Five records stand for the JSON objects the subsystems hand each other and write to disk:

- :class:`Provenance`: where a bank entry came from (a sidecar's ``source``: its kind, video, parent scenario,
  seed, generator; for a mined entry also the failure, cluster, reproduction rate, E2E-SC and replay parameters).
- :class:`Sidecar`: a bank entry's ``meta.json`` (description, elements, story, tags, map, provenance, hash).
- :class:`EpisodeRecord`: one episode of a failure-mining run, a line of its ``episodes.jsonl`` (the scene, the
  policy's result and failure, the reference driver's outcome, the sampler's point). Its ``result`` is an
  :class:`EpisodeOutcome` (the policy's outcome measures), its ``failure`` a :class:`Failure` (what the failure
  monitors found), its ``reference`` a :class:`ReferenceOutcome` (the reference driver's episode on the same scene)
  and its ``behaviour`` a :class:`Behaviour` (who else was involved and what each side was doing).
- :class:`RegressEpisode`: one policy's episode of a regression run, a line of its ``results.jsonl`` and a result
  in its report (the episode's outcome measures, the failure kinds it counts, its trace, or the error it ended in).
- :class:`HeldOutEpisode`: one episode of a loop's held-out evaluation, a line of a round's ``heldout.jsonl`` (the
  role and policy, the scene, whether the policy failed and how (a :class:`Failure`), its result (an
  :class:`EpisodeOutcome`), or the error it ended in).

Each is a frozen dataclass (a :class:`JsonRecord`) with :meth:`from_dict` (checks every field it knows; a
:class:`RecordError` names the bad one and what it should hold) and :meth:`to_dict`, which gives back exactly the
JSON object the files hold: the fields a record does not know travel in ``extra``, and a field that is ``None`` is
written as ``null`` only when the file format always writes it (or the object read had it as ``null``:
``null_fields``), so reading a file and writing it back changes no byte. A record is read by its attributes
(``record.seed``, ``record.failure``); it is no mapping: its JSON object is :meth:`JsonRecord.to_dict`. Two records
are equal when they are of one type and their JSON objects are equal; a record is never equal to a dict (compare
its :meth:`JsonRecord.to_dict`) and is always true (whether a record read from ``{}`` holds anything is
:func:`recorded`).
"""

from __future__ import annotations

import collections.abc
import dataclasses
import math
import re
import typing
import unicodedata
from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple, Union

from scenario_bank.elements import ElementError, Elements
from scenario_bank.errors import BankVersionError, DV2SError
from scenario_bank.safe_files import UnsafeInputError, is_entry_name, validate_relative_path
from scenario_bank.story import StoryError, normalize_story

__all__ = ["RecordError", "JsonRecord", "recorded", "Provenance", "Sidecar", "EpisodeRecord", "RegressEpisode",
           "HeldOutEpisode", "Failure", "Behaviour", "EpisodeOutcome", "ReferenceOutcome", "UNKNOWN_PART",
           "BEHAVIOUR_PARTS",
           "SOURCE_KINDS", "PROVENANCE_FIELDS", "MINED_PROVENANCE_FIELDS", "ENTRY_FILES",
           "SIDECAR_VERSION", "SCRIPT", "SIDECAR", "CONTROL_FIX", "control_character_field", "is_entry_file"]

SCRIPT = "scenario.scenic"
"""A bank entry's script, in its folder."""
SIDECAR = "meta.json"
"""A bank entry's sidecar (:class:`Sidecar`), in its folder."""

SIDECAR_VERSION = 1
"""Version of the ``meta.json`` sidecar format written by this code."""
SOURCE_KINDS = ("hand-written", "generated", "mined")
"""The kinds of bank entries: written by hand, generated from a video, mined from a policy's failure."""
PROVENANCE_FIELDS = ("kind", "video", "parent", "seed", "generator", "model", "context_hash", "date")
"""Provenance every new sidecar writes (``null`` when unknown)."""
MINED_PROVENANCE_FIELDS = ("params", "backends", "policy", "failure", "cluster", "reproduction", "e2e_sc", "run", "trace",
                           "index", "merged", "interaction", "judge", "replay", "replay_entry", "converted")
"""Extra provenance of ``kind == "mined"`` entries (failure mining): the parent's sampled parameters, the
DRA/SG backends, the policy that failed, its failure and cluster, the reproduction rate and E2E-SC, the
mining run and episode index, ``merged``: later failures merged into this entry (see ``Bank.add`` with
``on_duplicate="merge"``), ``interaction``: the failure's actor and manoeuvre read from its trace, ``judge``: the
checks the converted script passed, ``replay``: on an exact replay of the failing scene, the parameters, seed
and trajectory hash that pin it, and the links between the two entries of one failure (``replay_entry`` on the
converted script, ``converted`` on the replay). Sidecars without them (every older sidecar) load as before."""
ENTRY_FILES = "files"
"""The provenance field listing the files an entry carries in its own folder (relative paths), in ``source``
and in each ``source.merged`` record. They are added with the entry (``files=`` of ``Bank.add``), travel with
``Bank.export``, ``Bank.import_archive`` and ``Bank.copy_to``, and ``dv2s bank validate`` reports one that is
missing. Older sidecars have none."""


_ENTRY_FILE = re.compile(r"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]*(/[A-Za-z0-9_\-][A-Za-z0-9_.\-]*)*$")


def is_entry_file(name: Any) -> bool:
    """Whether ``name`` is a valid file name inside an entry folder (relative, at most 8 parts each a safe
    name (:func:`~scenario_bank.safe_files.validate_relative_path`), no hidden parts, not the script or sidecar)."""
    if not (isinstance(name, str) and bool(_ENTRY_FILE.match(name)) and name not in (SCRIPT, SIDECAR)):
        return False
    try:
        validate_relative_path(name)
    except UnsafeInputError:
        return False
    return True


def control_character_field(value: Any, where: str = "") -> Optional[str]:
    """The first field of ``value`` (a sidecar or part of one) whose text holds a control character
    other than a newline or a tab (terminal escape sequences start with one), or ``None``."""
    if isinstance(value, str):
        return where if any(unicodedata.category(c) == "Cc" and c not in "\n\t" for c in value) else None
    if isinstance(value, dict):
        items = [(str(k), v) for k, v in value.items()] + [(str(k), str(k)) for k in value]
    elif isinstance(value, (list, tuple)):
        items = [(f"[{k}]", v) for k, v in enumerate(value)]
    else:
        return None
    for key, item in items:
        found = control_character_field(item, f"{where}{key}" if key.startswith("[") or not where else f"{where}.{key}")
        if found is not None:
            return found
    return None


CONTROL_FIX = ("control characters (escape sequences, carriage returns, ...) are not allowed in a bank "
                "entry's description, tags or other sidecar text; remove them")


class RecordError(DV2SError, ValueError):
    """A record read from a file or handed over by other code has a field of the wrong kind; the message names
    the record, the field and what it should hold."""


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _json_object(value: Any) -> Any:
    """``value``, a record as its JSON object (what a record's JSON object field holds)."""
    return value.to_dict() if isinstance(value, (JsonRecord, Elements)) else value


def _is_object(value: Any) -> bool:
    """Whether ``value`` is a JSON object, or a record (whose JSON object is one)."""
    return isinstance(value, (Mapping, JsonRecord, Elements))


_CHECKS = {
    "str": (lambda v: isinstance(v, str), "a string"),
    "int": (_is_int, "an integer"),
    "number": (_is_number, "a number"),
    "bool": (lambda v: isinstance(v, bool), "true or false"),
    "object": (_is_object, "a JSON object"),
    "list": (lambda v: isinstance(v, (list, tuple)), "a list"),
    "strings": (lambda v: isinstance(v, (list, tuple)) and all(isinstance(s, str) for s in v), "a list of strings"),
    "objects": (lambda v: isinstance(v, (list, tuple)) and all(_is_object(s) for s in v),
                "a list of JSON objects"),
    "any": (lambda v: True, "anything"),
}


def _items_json(value: Any) -> Any:
    """The JSON form of an ``_ITEMS`` field: its records as JSON objects (an item that is no record as it is)."""
    def plain(item: Any) -> Any:
        return item.to_dict() if isinstance(item, JsonRecord) else item
    if isinstance(value, Mapping):
        return {name: plain(item) for name, item in value.items()}
    return [plain(item) for item in value]


_JSON_KINDS = {str: "str", bool: "bool", int: "int", float: "number"}
"""The JSON kinds (:data:`_CHECKS`) of fields annotated with plain types (a ``str`` subclass, such as a
``StrEnum``, is a string too)."""
_RECORD_FIELDS = ("extra", "null_fields")
"""The fields every record has that are no key of its JSON object."""


def _optional_of(annotation: Any) -> Any:
    """``X`` of ``Optional[X]``; any other annotation as it is."""
    if typing.get_origin(annotation) is Union:
        args = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
        if len(args) == 1:
            return args[0]
    return annotation


def _is_record_type(annotation: Any) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, JsonRecord)


def _annotation_kind(annotation: Any) -> Optional[Tuple[str, Optional[str], Optional[type]]]:
    """``(kind, role, record type)`` of a field annotated ``annotation``: its JSON kind, and how
    :meth:`JsonRecord.from_dict` reads it (``"nested"``: a record, ``"items"``: a tuple or mapping of records of the
    record type, ``"list"``: a tuple; ``None``: as it is); ``None`` for an annotation that does not say."""
    annotation = _optional_of(annotation)
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is Any:
        return "any", None, None
    if _is_record_type(annotation):
        return "object", "nested", annotation
    if isinstance(annotation, type) and issubclass(annotation, str):
        return "str", None, None
    if annotation in _JSON_KINDS:
        return _JSON_KINDS[annotation], None, None
    if origin in (dict, collections.abc.Mapping):
        return ("object", "items", args[1]) if args and _is_record_type(args[1]) else ("object", None, None)
    if origin is tuple:
        item = args[0] if args else Any
        if _is_record_type(item):
            return "objects", "items", item
        if typing.get_origin(item) in (dict, collections.abc.Mapping):
            return "objects", "list", None
        return ("strings" if item is str else "list"), "list", None
    return None


def _field_tables(cls: type) -> Dict[str, Any]:
    """The tables :class:`JsonRecord` reads a record class's JSON object by, derived from its fields' annotations
    in their order (the JSON object's order): ``_KINDS`` (each JSON key's kind; ``_KIND_OVERRIDES`` replaces a
    kind its annotation does not give), ``_NESTED``, ``_ITEMS`` and ``_LISTS``."""
    tables: Dict[str, Any] = {"_KINDS": {}, "_NESTED": {}, "_ITEMS": {}, "_LISTS": ()}
    if not dataclasses.is_dataclass(cls):
        return tables
    hints, keys = typing.get_type_hints(cls), {attribute: key for key, attribute in cls._ATTRIBUTES.items()}
    lists = []
    for item in dataclasses.fields(cls):
        key = keys.get(item.name, item.name)
        if item.name in _RECORD_FIELDS or (key in cls._KIND_OVERRIDES and cls._KIND_OVERRIDES[key] is None):
            continue
        derived = _annotation_kind(hints[item.name])
        if derived is None and key not in cls._KIND_OVERRIDES:
            raise RecordError(f"{cls.__qualname__}.{item.name}: the JSON kind of {hints[item.name]!r} is not known; "
                            f"give it in {cls.__qualname__}._KIND_OVERRIDES")
        kind, role, record = derived or (None, None, None)
        tables["_KINDS"][key] = cls._KIND_OVERRIDES.get(key, kind)
        if role == "nested":
            tables["_NESTED"][key] = record
        elif role == "items":
            tables["_ITEMS"][key] = record
        elif role == "list":
            lists.append(key)
    tables["_LISTS"] = tuple(lists)
    return tables


class _FieldTable:
    """A table of a record class (``_KINDS``, ``_NESTED``, ``_ITEMS`` or ``_LISTS``) derived from its fields'
    annotations on first use (:func:`_field_tables`); a class that sets the table itself keeps its own."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, record: Any, owner: type) -> Any:
        tables = owner.__dict__.get("_derived_tables")
        if tables is None:
            tables = _field_tables(owner)
            setattr(owner, "_derived_tables", tables)
        return tables[self.name]


class JsonRecord:
    """What the records share (those of this module, and the other typed records of files the product writes,
    such as a loop's rounds): the JSON form (:meth:`to_dict`), reading from it (:meth:`from_dict`) and equality
    by it (records of one type with equal JSON objects are equal; a record is not a mapping and never equals a
    dict). A subclass is a frozen dataclass whose fields are the keys of its JSON object, in the object's order
    (but ``extra`` and ``null_fields``); their annotations give each key's JSON kind (``_KINDS``: ``str``, ``int``,
    ``float`` a number, ``bool``, ``Any``, a ``Mapping`` an object, ``Tuple[str, ...]`` a list of strings, another
    tuple a list), the fields nested records fill (``_NESTED``: a record type), the lists or objects of records of
    one type (``_ITEMS``: ``Tuple[Record, ...]``, ``Mapping[str, Record]``) and the lists read as tuples
    (``_LISTS``). It sets, in ``_KIND_OVERRIDES``, the kind of a key its annotation does not give (or ``None``:
    the field is no key of its own), the fields :meth:`from_dict` needs in ``_REQUIRED`` and, in ``_ATTRIBUTES``,
    a JSON key held by an attribute of another name (a key that is also one of the record's own attribute
    names)."""

    _KINDS = _FieldTable()
    _NESTED = _FieldTable()
    _ITEMS = _FieldTable()
    _LISTS = _FieldTable()
    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {}
    _ATTRIBUTES: ClassVar[Dict[str, str]] = {}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ()
    _WHAT: ClassVar[str] = "record"

    def default_null_fields(self) -> FrozenSet[str]:
        """The fields :meth:`to_dict` writes as ``null`` when they are ``None`` and ``null_fields`` is not given:
        the ones the file format always writes."""
        return frozenset()

    @classmethod
    def json_fields(cls) -> FrozenSet[str]:
        """The keys of the JSON object this record type knows (each a field; any other key is kept in ``extra``)."""
        return frozenset(cls._KINDS)

    @classmethod
    def has_required(cls, data: Mapping[str, Any]) -> bool:
        """Whether ``data`` holds every field :meth:`from_dict` needs (each present and not ``null``)."""
        return all(data.get(key) is not None for key in cls._REQUIRED)

    @classmethod
    def from_dict(cls, data: Union["JsonRecord", Mapping[str, Any]]):
        """The record of ``data`` (a JSON object as the files hold it, or a record: one of this type as it is,
        another read from its JSON object), every known field checked; :class:`RecordError` names a field of the
        wrong kind or a required one that is missing."""
        if isinstance(data, cls):
            return data
        data = _json_object(data)
        if not isinstance(data, Mapping):
            raise RecordError(f"a {cls._WHAT} must be a JSON object, not {type(data).__name__}")
        for key in cls._REQUIRED:
            if data.get(key) is None:
                raise RecordError(f"{cls._WHAT} field {key!r} is missing; "
                                  f"every {cls._WHAT} has {', '.join(repr(k) for k in cls._REQUIRED)}")
        values: Dict[str, Any] = {}
        for key, kind in cls._KINDS.items():
            if key not in data or data[key] is None:
                continue
            value = data[key]
            check, wanted = _CHECKS[kind]
            if not check(value):
                raise RecordError(f"{cls._WHAT} field {key!r} must be {wanted}, not {_shown(value)}")
            if key in cls._NESTED:
                value = cls._nested(key, value)
            elif key in cls._ITEMS:
                value = cls._items(key, value, cls._ITEMS[key].from_dict)
            elif key in cls._LISTS:
                value = tuple(value)
            values[cls._ATTRIBUTES.get(key, key)] = value
        values.update(cls._check_extra(data))
        values["extra"] = {k: v for k, v in data.items() if k not in cls._KINDS}
        values["null_fields"] = frozenset(k for k in cls._KINDS if k in data and data[k] is None)
        return cls(**values)

    @classmethod
    def from_checked(cls, data: Mapping[str, Any]):
        """The record of ``data``, the :meth:`to_dict` of a record this code read with :meth:`from_dict` and kept
        (a bank's index of its sidecars): its fields are taken as they are, not checked again."""
        values: Dict[str, Any] = {}
        for key in cls._KINDS:
            value = data.get(key)
            if value is None:
                continue
            if key in cls._NESTED:
                value = cls._NESTED[key].from_checked(value)
            elif key in cls._ITEMS:
                value = cls._items(key, value, cls._ITEMS[key].from_checked)
            elif key in cls._LISTS:
                value = tuple(value)
            values[cls._ATTRIBUTES.get(key, key)] = value
        values["extra"] = {k: v for k, v in data.items() if k not in cls._KINDS}
        values["null_fields"] = frozenset(k for k in cls._KINDS if k in data and data[k] is None)
        return cls(**values)

    @classmethod
    def _nested(cls, key: str, value: Mapping[str, Any]) -> Any:
        """The nested record of field ``key``; its errors name the field from this record (``source.kind``)."""
        nested = cls._NESTED[key]
        try:
            return nested.from_dict(value)
        except RecordError as error:
            text, inner = str(error), f"{nested._WHAT} field '"
            if text.startswith(inner):
                raise RecordError(f"{cls._WHAT} field '{key}.{text[len(inner):]}") from None
            raise RecordError(f"{cls._WHAT} field {key!r}: {text}") from None

    @classmethod
    def _items(cls, key: str, value: Any, read: Any) -> Any:
        """The records of field ``key``, a JSON list (a tuple back) or object (a dict back) of records of one type
        (``_ITEMS``), each read by ``read``; its errors name the item (``episodes[3]``, ``scenarios.name``)."""
        items = value.items() if isinstance(value, Mapping) else enumerate(value)
        out = {}
        for index, item in items:
            try:
                out[index] = read(item)
            except RecordError as error:
                where = f"{key}.{index}" if isinstance(value, Mapping) else f"{key}[{index}]"
                raise RecordError(f"{cls._WHAT} field {where!r}: {error}") from None
        return out if isinstance(value, Mapping) else tuple(out.values())

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        """Checks of a subclass beyond the fields' kinds; the values they replace."""
        return {}

    def to_dict(self) -> Dict[str, Any]:
        """The JSON object of this record, as the files hold it (a new dict each call)."""
        nulls = self.default_null_fields() if self.null_fields is None else self.null_fields
        out: Dict[str, Any] = {}
        for key in self._KINDS:
            value = getattr(self, self._ATTRIBUTES.get(key, key))
            if value is None:
                if key in nulls:
                    out[key] = None
                continue
            if isinstance(value, (JsonRecord, Elements)):
                value = value.to_dict()
            elif key in self._ITEMS:
                value = _items_json(value)
            elif key in self._LISTS:
                value = list(value)
            out[key] = value
        out.update(self.extra)
        return out

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]  # equal by a JSON object that may hold dicts

    def replace(self, **changes: Any):
        """A copy with ``changes`` (field names) applied; the record is frozen."""
        return dataclasses.replace(self, **changes)


def recorded(record: Optional[JsonRecord]) -> bool:
    """Whether ``record`` (a record or a part of one) holds anything: ``None`` and a record whose JSON object is
    empty (read from ``{}``, such as a loop step recorded as ``{}``) hold nothing. A record itself is always true."""
    return record is not None and bool(record.to_dict())


def _shown(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text[:60] + '...' if len(text) > 60 else text}"


@dataclass(frozen=True, eq=False)
class Provenance(JsonRecord):
    """Where a bank entry came from: a sidecar's ``source``.

    ``kind`` is one of :data:`SOURCE_KINDS`; ``video``, ``parent`` (the bank scenario a mined or converted entry
    derives from), ``seed``, ``generator`` (the backends that wrote the script), ``model``, ``context_hash``
    (the prompt context) and ``date`` are what every entry records (:data:`PROVENANCE_FIELDS`). A mined entry
    adds :data:`MINED_PROVENANCE_FIELDS`: the failing scene's ``params``, ``backends``, ``policy``, its
    ``failure`` and ``cluster``, ``reproduction`` and ``e2e_sc`` (how well the new script replays the failure),
    the mining ``run`` and episode ``index``, its ``trace``, ``interaction``, the ``judge``'s checks, the
    ``replay`` parameters that pin an exact replay, the ``replay_entry``/``converted`` links between the two
    entries of one failure and ``merged`` (later failures merged into the entry). ``files`` lists the files the
    entry carries in its folder; ``converted_video`` names the one of them that films the converted script driven
    by the policy that failed (one reproduction episode, described by ``reproduction["clip"]``), written only when
    there is one. An entry whose script was upgraded from Scenic 2 lists what changed (``scenic2_rewrites``) and
    what to check by hand (``scenic2_notes``). Other keys (links added later) are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default :data:`PROVENANCE_FIELDS`, and a
    mined entry's :data:`MINED_PROVENANCE_FIELDS` but ``merged``, as a new sidecar writes them.
    """

    kind: Optional[str] = None
    video: Optional[str] = None
    parent: Optional[str] = None
    seed: Optional[int] = None
    generator: Optional[str] = None
    model: Optional[str] = None
    context_hash: Optional[str] = None
    date: Optional[str] = None
    params: Optional[Mapping[str, Any]] = None
    backends: Optional[Mapping[str, Any]] = None
    policy: Optional[str] = None
    failure: Optional[Mapping[str, Any]] = None
    cluster: Optional[str] = None
    reproduction: Optional[Mapping[str, Any]] = None
    e2e_sc: Optional[Any] = None
    run: Optional[str] = None
    trace: Optional[str] = None
    index: Optional[int] = None
    merged: Optional[Tuple[Mapping[str, Any], ...]] = None
    interaction: Optional[Mapping[str, Any]] = None
    judge: Optional[Mapping[str, Any]] = None
    replay: Optional[Mapping[str, Any]] = None
    replay_entry: Optional[str] = None
    converted: Optional[str] = None
    files: Optional[Tuple[str, ...]] = None
    converted_video: Optional[str] = None
    scenic2_rewrites: Optional[Tuple[str, ...]] = None
    scenic2_notes: Optional[Tuple[str, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "provenance"

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        kind = data.get("kind")
        if kind is not None and kind not in SOURCE_KINDS:
            raise RecordError(f"provenance kind (field 'kind') must be one of {SOURCE_KINDS}, not {_shown(kind)}")
        return {}

    def default_null_fields(self) -> FrozenSet[str]:
        mined = (key for key in MINED_PROVENANCE_FIELDS if key != "merged") if self.kind == "mined" else ()
        return frozenset(PROVENANCE_FIELDS) | frozenset(mined)

    @property
    def mined(self) -> bool:
        """Whether the entry was mined from a policy's failure."""
        return self.kind == "mined"

    @property
    def failure_type(self) -> Optional[str]:
        """The type of the mined failure (``"collision"``, ``"off_road"``, ...), or ``None``."""
        return (self.failure or {}).get("type")

    @property
    def is_replay(self) -> bool:
        """Whether the entry is an exact replay of a failing scene (it carries ``replay`` parameters)."""
        return bool(self.replay)


@dataclass(frozen=True, eq=False)
class Sidecar(JsonRecord):
    """A bank entry's ``meta.json``: ``description`` (natural language), ``elements`` (:class:`~scenario_bank.elements.Elements`: road, participants,
    actions, relations), optional ``story`` (the phases of the scenario), ``tags``, ``map``, ``use_case``,
    its provenance ``source`` (:class:`Provenance`), the script's ``content_hash``, the entry ``name`` and the
    format's ``schema_version``. Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every field a new sidecar writes
    (all but ``story``).
    """

    schema_version: Optional[int] = None
    name: Optional[str] = None
    description: str = ""
    elements: Optional[Elements] = None
    story: Optional[Any] = None
    tags: Tuple[str, ...] = ()
    map: str = ""
    use_case: Optional[str] = None
    source: Optional[Provenance] = None
    content_hash: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("description", "map")
    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"elements": "object"}
    _WHAT: ClassVar[str] = "sidecar"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS) - {"story"}

    @classmethod
    def from_dict(cls, data: Union["JsonRecord", Mapping[str, Any]]) -> "Sidecar":
        """The sidecar of ``data``, its format checked (the one place it is): a JSON object with no control
        character in its text, of a ``schema_version`` this dv2s-gym reads (:class:`BankVersionError`
        otherwise), a non-empty ``description`` and ``map``, valid elements and story, a provenance of a known
        ``kind``, a valid entry ``name`` and entry files inside the entry folder; a :class:`RecordError` names what
        is wrong."""
        if isinstance(data, cls):
            return data
        data = _json_object(data)
        if not isinstance(data, Mapping):
            raise RecordError(f"a sidecar must be a JSON object, not {type(data).__name__}")
        field_name = control_character_field(dict(data))
        if field_name is not None:
            raise RecordError(f"sidecar field {field_name!r} holds a control character: {CONTROL_FIX}")
        version = data.get("schema_version", 1)
        if not _is_int(version) or version > SIDECAR_VERSION:
            raise BankVersionError(
                f"sidecar schema_version {version!r} is newer than this dv2s-gym supports ({SIDECAR_VERSION}); upgrade")
        for key in ("description", "map"):
            if not isinstance(data.get(key), str) or not data.get(key):
                raise RecordError(f"sidecar field {key!r} is missing or not a non-empty string")
        return super().from_dict(data)

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        try:
            elements = Elements.from_dict(data.get("elements") or {})
        except ElementError as error:
            raise RecordError(f"sidecar elements: {error}") from None
        if "story" in data:
            try:
                normalize_story(data["story"], "sidecar story")
            except StoryError as error:
                raise RecordError(str(error)) from None
        source = _json_object(data.get("source")) or {}
        if source.get("kind") not in SOURCE_KINDS:
            raise RecordError(f"sidecar source.kind must be one of {SOURCE_KINDS}, got {source.get('kind')!r}")
        if "name" in data and not is_entry_name(data["name"]):
            raise RecordError(f"sidecar field 'name' {str(data['name'])[:80]!r} is not a valid entry name; "
                              "set it to the entry folder's name")
        merged = source.get("merged") or []
        for where, record in [("source", source)] + [(f"source.merged[{k}]", m) for k, m in enumerate(merged)]:
            for file in record.get(ENTRY_FILES) or []:
                if not is_entry_file(file):
                    raise RecordError(f"sidecar field '{where}.{ENTRY_FILES}' names {str(file)[:80]!r}, which is not "
                                      "a file inside the entry folder: list relative paths of letters, digits, '_', "
                                      "'-', '.' and '/' only (no '..', not absolute)")
        return {"elements": elements} if data.get("elements") is not None else {}

    @classmethod
    def from_checked(cls, data: Mapping[str, Any]) -> "Sidecar":
        record = super().from_checked(data)
        if record.elements is None:
            return record
        return record.replace(elements=Elements.from_dict(record.elements))

    @property
    def provenance(self) -> Provenance:
        """The entry's provenance (an empty one when the sidecar has none)."""
        return self.source if self.source is not None else Provenance(null_fields=frozenset())


def _read_nested(record: JsonRecord) -> None:
    """Read the nested records of ``record`` given as JSON objects (code that builds a record from the files' dict
    form) into their records, checked as :meth:`JsonRecord.from_dict` checks them."""
    for key, nested in record._NESTED.items():
        attribute = record._ATTRIBUTES.get(key, key)
        value = getattr(record, attribute)
        if value is not None and not isinstance(value, nested):
            object.__setattr__(record, attribute, record._nested(key, value))


UNKNOWN_PART = "unknown"
"""What a :class:`Behaviour` says of a part its record or trace cannot tell."""
BEHAVIOUR_PARTS = ("actor", "actor_manoeuvre", "ego_manoeuvre")
"""The parts of a :class:`Behaviour`, in the order its JSON object holds them."""


@dataclass(frozen=True, eq=False)
class Failure(JsonRecord):
    """One failure of an episode, as the failure monitors (:mod:`dv2s_gym.mining.monitors`) find it and episode
    records hold it: its ``type`` (a row of :mod:`scenario_bank.failure_types`), ``time`` [s] and ``step``; the
    other actor it was ``with_`` (JSON ``with``) and that actor's kind (``with_kind``), how a collision happened
    (``collision_type``), the smallest time to collision (``min_ttc``) and the ego's ``speed`` [m/s] at the failure.
    :attr:`kind` is ``type`` refined by the collision type. A failure's JSON object holds ``kind`` too: the one read
    is the failure's kind and is written back as it was (``recorded_kind``); a new failure writes its own. Other
    keys (a plug-in's) are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every one, as the monitors write a
    failure.
    """

    type: str
    time: Optional[float] = None
    step: Optional[int] = None
    with_: Optional[str] = None
    with_kind: Optional[str] = None
    collision_type: Optional[str] = None
    min_ttc: Optional[float] = None
    speed: Optional[float] = None
    recorded_kind: Optional[str] = None
    """The ``kind`` the failure's JSON object holds (a new failure's own :attr:`kind`; ``None``: it holds none)."""
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # The JSON object's order is not the fields' (the positional constructor detectors call keeps its order).
    _KINDS: ClassVar[Dict[str, str]] = {
        "type": "str", "time": "number", "step": "int", "with_kind": "str", "collision_type": "str",
        "min_ttc": "number", "speed": "number", "with": "str", "kind": "str",
    }
    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"with": "with_", "kind": "recorded_kind"}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("type",)
    _WHAT: ClassVar[str] = "failure"

    def __post_init__(self) -> None:
        if self.null_fields is None and self.recorded_kind is None:  # a new failure, not one read from JSON
            object.__setattr__(self, "recorded_kind", self.kind)

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS)

    @property
    def kind(self) -> str:
        """``type`` refined by the collision type (``"collision:rear_end"``): the failure class a reproduction must
        show; the one the JSON object holds when it holds one."""
        return self.recorded_kind or (f"{self.type}:{self.collision_type}" if self.collision_type else self.type)

    @classmethod
    def of(cls, value: Union["Failure", Mapping[str, Any], None]) -> Optional["Failure"]:
        """The failure ``value`` holds (a failure, its JSON object as a file holds it, or ``None``); ``None`` when it
        holds none (``None`` or an empty object)."""
        return cls.from_dict(value) if value else None

    def completed_by(self, other: "Failure") -> "Failure":
        """This failure with each field it leaves out (``None``) taken from ``other``, the same failure found again
        (its episode re-run): a failure record written by hand may hold only its type. The JSON object written
        holds the fields either one's does."""
        changes = {item.name: getattr(other, item.name) for item in dataclasses.fields(self)
                   if item.name not in ("extra", "null_fields") and getattr(self, item.name) is None}
        mine, theirs = (record.default_null_fields() if record.null_fields is None else record.null_fields
                        for record in (self, other))
        nulls = None if self.null_fields is None and other.null_fields is None else mine | theirs
        return self.replace(**changes, extra={**other.extra, **self.extra}, null_fields=nulls)

    def to_json(self) -> Dict[str, Any]:
        """The failure's JSON object (:meth:`to_dict`): ``with_`` is stored as ``with``, with the ``kind``."""
        return self.to_dict()

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "Failure":
        """The failure of its JSON object (:meth:`from_dict`)."""
        return cls.from_dict(data)


@dataclass(frozen=True, eq=False)
class Behaviour(JsonRecord):
    """What happened in a failure (:mod:`dv2s_gym.mining.behaviour`): the kind of the other ``actor`` involved
    (``"car"``, ``"truck"``, ``"pedestrian"``, ...; ``"none"`` without one), what it was doing
    (``actor_manoeuvre``) and what the ego was doing (``ego_manoeuvre``); ``"unknown"`` where the trace cannot tell
    it. A behaviour read from a JSON object holds its parts as the object does (``None`` for one it leaves out or
    holds as ``null``, and writes them back so); :meth:`complete` reads such a part as ``"unknown"``. Other keys are
    kept in ``extra``.

    ``null_fields``: the parts written as ``null`` when ``None``; by default none.
    """

    actor: Optional[str] = None
    actor_manoeuvre: Optional[str] = None
    ego_manoeuvre: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "behaviour"

    def complete(self) -> "Behaviour":
        """This behaviour with ``"unknown"`` for each part it does not tell (``None`` or empty), as the reports
        and the clusters read it."""
        parts = {key: getattr(self, key) or UNKNOWN_PART for key in BEHAVIOUR_PARTS}
        return self if all(getattr(self, key) for key in BEHAVIOUR_PARTS) else Behaviour(**parts)


@dataclass(frozen=True, eq=False)
class EpisodeOutcome(JsonRecord):
    """The outcome of one episode of one policy as the files hold it: the ``result`` of an episode record
    (:class:`EpisodeRecord`, :class:`HeldOutEpisode`), the JSON object of
    :meth:`policies.evaluation.EpisodeResult.to_json` (``EpisodeResult.to_record`` reads it into this record).

    The episode's ``scenario``, env ``seed``, ``scene_seed`` and the script's sampled ``params``; whether the ego
    ``collided`` and with whom (``collisions``), went ``off_road`` or drove on to a ``success``; the smallest time
    to collision ``min_ttc`` [s] (``None`` when nothing ever closed in), ``mean_speed`` [m/s], ``distance`` [m],
    ``episode_return``, ``steps`` and the ``trajectory_hash`` a replay must match; the ``error`` the episode ended
    in, the result's own ``extra`` object (JSON ``extra``: when and with whom the smallest time to collision came),
    held here as ``result_extra``, and whether the policy ``failed`` (a collision or leaving the road). Each field
    is optional: a result read from a file may hold only some (a record written by hand, such as a test's, may
    hold only its ``trajectory_hash``). Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every one, as ``to_json`` writes a
    result.
    """

    scenario: Optional[str] = None
    seed: Optional[int] = None
    scene_seed: Optional[int] = None
    params: Optional[Mapping[str, Any]] = None
    collided: Optional[bool] = None
    collisions: Optional[Tuple[Any, ...]] = None
    off_road: Optional[bool] = None
    success: Optional[bool] = None
    min_ttc: Optional[float] = None
    mean_speed: Optional[float] = None
    distance: Optional[float] = None
    episode_return: Optional[float] = None
    steps: Optional[int] = None
    trajectory_hash: Optional[str] = None
    error: Optional[str] = None
    result_extra: Optional[Mapping[str, Any]] = None
    """The result's own ``extra`` object (JSON ``extra``)."""
    failed: Optional[bool] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"extra": "result_extra"}
    _WHAT: ClassVar[str] = "episode result"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS)


@dataclass(frozen=True, eq=False)
class ReferenceOutcome(JsonRecord):
    """The reference driver's episode on the scene a policy failed in: the ``reference`` of an episode record
    (:class:`EpisodeRecord`), as the miner writes it. The reference ``policy``'s spec, its ``failure`` (a
    :class:`Failure`; ``None`` when it drove safely), the episode's ``trajectory_hash``, whether the ego ``collided``
    and its smallest time to collision ``min_ttc`` [s] (``None`` when nothing ever closed in). Each field is
    optional (a record written by hand may hold only some). Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every one, as the miner writes them.
    """

    policy: Optional[str] = None
    failure: Optional[Failure] = None
    trajectory_hash: Optional[str] = None
    collided: Optional[bool] = None
    min_ttc: Optional[float] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "reference outcome"

    def __post_init__(self) -> None:
        _read_nested(self)

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS)

    @property
    def failure_type(self) -> Optional[str]:
        """The type of the reference driver's failure, or ``None`` when it drove safely."""
        return self.failure.type if self.failure is not None else None


@dataclass(frozen=True, eq=False)
class EpisodeRecord(JsonRecord):
    """One episode of a failure-mining run: a line of the run's ``episodes.jsonl``.

    The scene: episode ``index``, ``scenario`` (and its ``family``: the bank scenario it derives from), env
    ``seed`` and the script's sampled ``params``; the ``policy`` run on it and its ``result`` (an
    :class:`EpisodeOutcome`: :meth:`policies.evaluation.EpisodeResult.to_json`), its ``failure`` (``type``,
    ``kind``, ``time``, ...; ``None`` when it drove safely), robustness ``rho``, the reference driver's outcome on
    the same scene (``reference``, a :class:`ReferenceOutcome`, and ``avoidable``), the saved ``trace`` of a failed
    episode (relative to the run folder), ``error`` (the episode could not run: no failure of the policy), a
    failure's ``behaviour`` (who else was involved and what each side was doing) and ``failure_state`` (the numbers
    describing the scene at the failure),
    the ``worker_restarts`` it survived, and the ``sampler`` with the ``point`` and ``proposal`` density it was drawn
    from. Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every field but ``behaviour``,
    ``failure_state`` and ``worker_restarts`` (written only when there is one), as the miner writes them.
    """

    index: int
    scenario: str
    seed: int
    policy: Optional[str] = None
    params: Optional[Mapping[str, Any]] = None
    result: Optional[EpisodeOutcome] = None
    failure: Optional[Failure] = None
    rho: Optional[float] = None
    reference: Optional[ReferenceOutcome] = None
    avoidable: Optional[bool] = None
    trace: Optional[str] = None
    error: Optional[str] = None
    family: Optional[str] = None
    behaviour: Optional[Behaviour] = None
    failure_state: Optional[Tuple[float, ...]] = None
    worker_restarts: Optional[Tuple[Any, ...]] = None
    sampler: Optional[str] = None
    point: Optional[Any] = None
    proposal: Optional[Any] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("index", "scenario", "seed")
    _WHAT: ClassVar[str] = "episode record"

    def __post_init__(self) -> None:
        _read_nested(self)

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS) - {"behaviour", "failure_state", "worker_restarts"}

    @property
    def id(self) -> str:
        """``"<scenario>/<seed>"``, the episode's name in reports."""
        return f"{self.scenario}/{int(self.seed)}"

    @property
    def failed(self) -> bool:
        """Whether the policy failed (an episode that could not run did not fail)."""
        return bool(self.failure) and not self.error

    @property
    def outcome(self) -> str:
        """``"error"``, ``"failed"`` or ``"passed"``."""
        return "error" if self.error else "failed" if self.failure else "passed"

    @property
    def failure_type(self) -> Optional[str]:
        """The failure's type (``"collision"``, ``"off_road"``, ``"stall"``, ``"low_ttc"``), or ``None``."""
        return self.failure.type if self.failure is not None and not self.error else None

    @property
    def mean_speed(self) -> Optional[float]:
        """The ego's mean speed over the episode (m/s), from its result; ``None`` without one."""
        value = self.result.mean_speed if self.result is not None else None
        return float(value) if _is_number(value) else None

    @property
    def min_ttc(self) -> float:
        """The episode's smallest time to collision (s); infinite when nothing came close or without a result."""
        value = self.result.min_ttc if self.result is not None else None
        return float(value) if _is_number(value) else math.inf



@dataclass(frozen=True, eq=False)
class RegressEpisode(JsonRecord):
    """One policy's episode of a regression run (``dv2s regress``): a line of the run's ``results.jsonl``, and a
    ``candidate`` or ``baseline`` result of its report's ``episodes``.

    The episode: its ``id`` (``"<scenario>/<seed>"``), the ``role`` of the policy (``"candidate"`` or
    ``"baseline"``), ``scenario`` and env ``seed``; the outcome measures of
    :meth:`policies.evaluation.EpisodeResult.to_json` (``scene_seed``, the script's sampled ``params``,
    ``collided`` and with whom (``collisions``), ``off_road``, ``success``, ``min_ttc`` (``None`` when nothing
    ever closed in), ``mean_speed``, ``distance``, ``episode_return``, ``steps``, ``trajectory_hash``, and its
    ``extra``, held here as ``result_extra``); whether the ego ``stalled`` and when (``stall_time``); the failure
    kinds of the run that happened (``failure_kinds``, from :data:`scenario_bank.failure_types.FAILURE_TABLE`)
    and whether any did (``failed``); the saved ``trace`` of a failed episode (relative to the run's folder).
    An episode that produced no result has only ``id``, ``role``, ``scenario``, ``seed``, its ``error`` and a
    ``null`` trace. Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default ``trace`` and, for an episode
    that ran, ``error``, ``min_ttc`` and ``stall_time``, as the runner writes them.
    """

    id: str
    role: str
    scenario: str
    seed: int
    scene_seed: Optional[int] = None
    params: Optional[Mapping[str, Any]] = None
    collided: Optional[bool] = None
    collisions: Optional[Tuple[Any, ...]] = None
    off_road: Optional[bool] = None
    success: Optional[bool] = None
    failed: Optional[bool] = None
    min_ttc: Optional[float] = None
    mean_speed: Optional[float] = None
    distance: Optional[float] = None
    episode_return: Optional[float] = None
    steps: Optional[int] = None
    trajectory_hash: Optional[str] = None
    error: Optional[str] = None
    result_extra: Optional[Mapping[str, Any]] = None
    """The result's own ``extra`` (when and with whom the smallest time to collision came)."""
    trace: Optional[str] = None
    stalled: Optional[bool] = None
    stall_time: Optional[float] = None
    failure_kinds: Optional[Tuple[str, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"extra": "result_extra"}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("id", "role", "scenario", "seed")
    _WHAT: ClassVar[str] = "regression result"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"trace"} if self.error else {"trace", "error", "min_ttc", "stall_time"})

    @property
    def key(self) -> Tuple[str, str]:
        """``(id, role)``: the episode's place in the run (one result each)."""
        return self.id, self.role


@dataclass(frozen=True, eq=False)
class HeldOutEpisode(JsonRecord):
    """One episode of a loop's held-out evaluation (:mod:`dv2s_gym.loop.heldout`): a line of a round's
    ``heldout.jsonl``.

    The ``role`` the policy was evaluated as (``before``, ``after``, ``control``...), the ``policy``, the bank
    ``scenario`` and env ``seed``; whether the policy ``failed`` and its ``failure`` (``type``, ``kind``, ``time``...;
    ``None`` when it drove safely), its ``result`` (an :class:`EpisodeOutcome`:
    :meth:`policies.evaluation.EpisodeResult.to_json`), or the ``error`` the episode ended in (``failed`` is then
    ``None``: no failure of the policy). Other keys are kept in ``extra``. Every field is written, ``null`` when
    ``None``.
    """

    role: str
    scenario: str
    seed: int
    policy: Optional[str] = None
    failed: Optional[bool] = None
    failure: Optional[Failure] = None
    result: Optional[EpisodeOutcome] = None
    error: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("role", "scenario", "seed")
    _WHAT: ClassVar[str] = "held-out episode"

    def __post_init__(self) -> None:
        _read_nested(self)

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS)
