"""Typed records of what travels between the bank, the miner, the regression runner and the policies.

Five records stand for the JSON objects the subsystems hand each other and write to disk:

- :class:`Provenance`: where a bank entry came from (a sidecar's ``source``: its kind, video, parent scenario,
  seed, generator; for a mined entry also the failure, cluster, reproduction rate, E2E-SC and replay parameters).
- :class:`Sidecar`: a bank entry's ``meta.json`` (description, elements, story, tags, map, provenance, hash).
- :class:`EpisodeRecord`: one episode of a failure-mining run, a line of its ``episodes.jsonl`` (the scene, the
  policy's result and failure, the reference driver's outcome, the sampler's point).
- :class:`RegressEpisode`: one policy's episode of a regression run, a line of its ``results.jsonl`` and a result
  in its report (the episode's outcome measures, the failure kinds it counts, its trace, or the error it ended in).
- :class:`HeldOutEpisode`: one episode of a loop's held-out evaluation, a line of a round's ``heldout.jsonl`` (the
  role and policy, the scene, whether the policy failed and how, its result, or the error it ended in).

Each is a frozen dataclass (a :class:`JsonRecord`) with :meth:`from_dict` (checks every field it knows; a
:class:`RecordError` names the bad one and what it should hold) and :meth:`to_dict`, which gives back exactly the
JSON object the files hold: the fields a record does not know travel in ``extra``, and a field that is ``None`` is
written as ``null`` only when the file format always writes it (or the object read had it as ``null``:
``null_fields``), so reading a file and writing it back changes no byte. The product reads a record by its
attributes (``record.seed``, ``record.failure``); a record is also a read-only mapping over its JSON object
(``record["seed"]``) for code written against the files' dict form. Whether a record read from ``{}`` holds anything
is :func:`recorded`.
"""

from __future__ import annotations

import dataclasses
import math
import re
import unicodedata
from collections.abc import Mapping as _MappingABC
from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Iterator, Mapping, Optional, Tuple, Union

from scenario_bank.elements import ElementError, Elements
from scenario_bank.errors import BankVersionError, DV2SError
from scenario_bank.safe_files import UnsafeInputError, is_entry_name, validate_relative_path
from scenario_bank.story import StoryError, normalize_story

__all__ = ["RecordError", "JsonRecord", "recorded", "Provenance", "Sidecar", "EpisodeRecord", "RegressEpisode",
           "HeldOutEpisode", "SOURCE_KINDS", "PROVENANCE_FIELDS", "MINED_PROVENANCE_FIELDS", "ENTRY_FILES",
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


class JsonRecord(_MappingABC):
    """What the records share (those of this module, and the other typed records of files the product writes,
    such as a loop's rounds): the JSON form (:meth:`to_dict`), reading from it (:meth:`from_dict`) and read-only
    mapping access to it. Subclasses list their fields' JSON kinds in ``_KINDS`` (a field missing
    from it is the record's ``extra`` or ``null_fields``), the fields :meth:`from_dict` needs in ``_REQUIRED``,
    the fields nested records fill in ``_NESTED``, the lists or objects of records of one type in ``_ITEMS``
    and, in ``_ATTRIBUTES``, a JSON key held by an attribute of another name (a key that is also one of the
    record's own attribute names)."""

    _KINDS: ClassVar[Dict[str, str]] = {}
    _ATTRIBUTES: ClassVar[Dict[str, str]] = {}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ()
    _NESTED: ClassVar[Dict[str, type]] = {}
    _ITEMS: ClassVar[Dict[str, type]] = {}
    _LISTS: ClassVar[Tuple[str, ...]] = ()
    _WHAT: ClassVar[str] = "record"

    def default_null_fields(self) -> FrozenSet[str]:
        """The fields :meth:`to_dict` writes as ``null`` when they are ``None`` and ``null_fields`` is not given:
        the ones the file format always writes."""
        return frozenset()

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

    def _json(self) -> Dict[str, Any]:
        cached = self.__dict__.get("_cached_json")
        if cached is None:
            cached = self.to_dict()
            object.__setattr__(self, "_cached_json", cached)
        return cached

    # Read-only mapping access to the JSON object, kept for code outside the product (the product reads fields).
    def __getitem__(self, key: str) -> Any:
        return self._json()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._json())

    def __len__(self) -> int:
        return len(self._json())

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

    _KINDS: ClassVar[Dict[str, str]] = {
        "kind": "str", "video": "str", "parent": "str", "seed": "int", "generator": "str", "model": "str",
        "context_hash": "str", "date": "str", "params": "object", "backends": "object", "policy": "str",
        "failure": "object", "cluster": "str", "reproduction": "object", "e2e_sc": "any", "run": "str",
        "trace": "str", "index": "int", "merged": "objects", "interaction": "object", "judge": "object",
        "replay": "object", "replay_entry": "str", "converted": "str", ENTRY_FILES: "strings",
        "converted_video": "str", "scenic2_rewrites": "strings", "scenic2_notes": "strings",
    }
    _LISTS: ClassVar[Tuple[str, ...]] = ("merged", ENTRY_FILES, "scenic2_rewrites", "scenic2_notes")
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

    description: str = ""
    map: str = ""
    name: Optional[str] = None
    schema_version: Optional[int] = None
    elements: Optional[Elements] = None
    story: Optional[Any] = None
    tags: Tuple[str, ...] = ()
    use_case: Optional[str] = None
    source: Optional[Provenance] = None
    content_hash: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {
        "schema_version": "int", "name": "str", "description": "str", "elements": "object", "story": "any",
        "tags": "strings", "map": "str", "use_case": "str", "source": "object", "content_hash": "str",
    }
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("description", "map")
    _NESTED: ClassVar[Dict[str, type]] = {"source": Provenance}
    _LISTS: ClassVar[Tuple[str, ...]] = ("tags",)
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


@dataclass(frozen=True, eq=False)
class EpisodeRecord(JsonRecord):
    """One episode of a failure-mining run: a line of the run's ``episodes.jsonl``.

    The scene: episode ``index``, ``scenario`` (and its ``family``: the bank scenario it derives from), env
    ``seed`` and the script's sampled ``params``; the ``policy`` run on it and its ``result``
    (:meth:`policies.evaluation.EpisodeResult.to_json`), its ``failure`` (``type``, ``kind``, ``time``, ...; ``None``
    when it drove safely), robustness ``rho``, the reference driver's outcome on the same scene (``reference``,
    ``avoidable``), the saved ``trace`` of a failed episode (relative to the run folder), ``error`` (the episode
    could not run: no failure of the policy), a failure's ``behaviour`` (who else was involved and what each side
    was doing) and ``failure_state`` (the numbers describing the scene at the failure), the
    ``worker_restarts`` it survived, and the ``sampler`` with the ``point`` and ``proposal`` density it was drawn
    from. Other keys are kept in ``extra``.

    ``null_fields``: the fields written as ``null`` when ``None``; by default every field but ``behaviour``,
    ``failure_state`` and ``worker_restarts`` (written only when there is one), as the miner writes them.
    """

    index: int
    scenario: str
    seed: int
    policy: Optional[str] = None
    params: Optional[Mapping[str, Any]] = None
    result: Optional[Mapping[str, Any]] = None
    failure: Optional[Mapping[str, Any]] = None
    rho: Optional[float] = None
    reference: Optional[Mapping[str, Any]] = None
    avoidable: Optional[bool] = None
    trace: Optional[str] = None
    error: Optional[str] = None
    family: Optional[str] = None
    behaviour: Optional[Mapping[str, Any]] = None
    failure_state: Optional[Tuple[float, ...]] = None
    worker_restarts: Optional[Tuple[Any, ...]] = None
    sampler: Optional[str] = None
    point: Optional[Any] = None
    proposal: Optional[Any] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {
        "index": "int", "scenario": "str", "seed": "int", "policy": "str", "params": "object", "result": "object",
        "failure": "object", "rho": "number", "reference": "object", "avoidable": "bool", "trace": "str",
        "error": "str", "family": "str", "behaviour": "object", "failure_state": "list",
        "worker_restarts": "list", "sampler": "str", "point": "any", "proposal": "any",
    }
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("index", "scenario", "seed")
    _LISTS: ClassVar[Tuple[str, ...]] = ("failure_state", "worker_restarts")
    _WHAT: ClassVar[str] = "episode record"

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
        return (self.failure or {}).get("type") if not self.error else None

    @property
    def mean_speed(self) -> Optional[float]:
        """The ego's mean speed over the episode (m/s), from its result; ``None`` without one."""
        value = (self.result or {}).get("mean_speed")
        return float(value) if _is_number(value) else None

    @property
    def min_ttc(self) -> float:
        """The episode's smallest time to collision (s); infinite when nothing came close or without a result."""
        value = (self.result or {}).get("min_ttc")
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

    _KINDS: ClassVar[Dict[str, str]] = {
        "id": "str", "role": "str", "scenario": "str", "seed": "int", "scene_seed": "int", "params": "object",
        "collided": "bool", "collisions": "list", "off_road": "bool", "success": "bool", "failed": "bool",
        "min_ttc": "number", "mean_speed": "number", "distance": "number", "episode_return": "number",
        "steps": "int", "trajectory_hash": "str", "error": "str", "extra": "object", "trace": "str",
        "stalled": "bool", "stall_time": "number", "failure_kinds": "strings",
    }
    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"extra": "result_extra"}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("id", "role", "scenario", "seed")
    _LISTS: ClassVar[Tuple[str, ...]] = ("collisions", "failure_kinds")
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
    ``None`` when it drove safely), its ``result`` (:meth:`policies.evaluation.EpisodeResult.to_json`), or the
    ``error`` the episode ended in (``failed`` is then ``None``: no failure of the policy). Other keys are kept in
    ``extra``. Every field is written, ``null`` when ``None``.
    """

    role: str
    scenario: str
    seed: int
    policy: Optional[str] = None
    failed: Optional[bool] = None
    failure: Optional[Mapping[str, Any]] = None
    result: Optional[Mapping[str, Any]] = None
    error: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {
        "role": "str", "scenario": "str", "seed": "int", "policy": "str", "failed": "bool", "failure": "object",
        "result": "object", "error": "str",
    }
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("role", "scenario", "seed")
    _WHAT: ClassVar[str] = "held-out episode"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset(self._KINDS)
