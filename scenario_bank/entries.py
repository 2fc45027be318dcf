"""A bank's entries: the layout of an entry folder, its sidecar (``meta.json``: checked, written), its provenance
and the files it carries, and the listing of a bank folder's entries.

An entry is a folder ``<name>/`` holding ``scenario.scenic`` and ``meta.json`` (description, elements, story,
tags, map, provenance ``source``, content hash), and the files its provenance lists (:data:`ENTRY_FILES`).
Every file is read through :mod:`scenario_bank.safe_files` (regular files only, never through a link,
size-capped, JSON depth-capped) and every name read from a folder or a sidecar is checked against one safe pattern.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from scenario_bank.dedup import content_hash, semantic_key
from scenario_bank.elements import ElementError, Elements
from scenario_bank.errors import BankError, BankVersionError, NotABankError, UnsafeBankInputError
from scenario_bank.records import (CONTROL_FIX, ENTRY_FILES, MINED_PROVENANCE_FIELDS, PROVENANCE_FIELDS, SCRIPT,
                                   SIDECAR, SIDECAR_VERSION, SOURCE_KINDS, Provenance, RecordError, Sidecar,
                                   control_character_field, is_entry_file)
from scenario_bank.safe_files import (ArchiveLimits, UnsafeInputError, is_entry_name, load_json_bounded,
                                      read_in_folder, regular_file_in_folder)

__all__ = [
    "BANK_VERSION", "SIDECAR_VERSION", "SOURCE_KINDS", "SCRIPT", "SIDECAR", "MAX_SCRIPT_BYTES", "MAX_SIDECAR_BYTES",
    "MAX_FILE_BYTES", "MAX_JSON_DEPTH", "MINED_PROVENANCE_FIELDS", "ENTRY_FILE_KEYS", "ENTRY_FILES", "entry_files",
    "entry_file_name", "ScenarioEntry", "Listing", "validate_sidecar", "new_sidecar", "new_provenance", "scan_entries",
    "entry_matches", "Provenance", "Sidecar", "NEW_ENTRY_NAME", "PathLike", "entry_bytes", "read_json", "read_text",
    "unsafe_input",
]

BANK_VERSION = 1
"""Version of the bank folder format written by this code."""
NEW_ENTRY_NAME = re.compile(r"^[a-z0-9][a-z0-9_\-]{0,99}$")
"""Names of new entries; an existing folder or an archive entry only needs a safe name (:func:`is_entry_name`)."""
MAX_SCRIPT_BYTES = ArchiveLimits.max_script_bytes
"""The largest ``scenario.scenic`` read from a bank folder or archive."""
MAX_SIDECAR_BYTES = ArchiveLimits.max_sidecar_bytes
"""The largest ``meta.json`` (or archive header) read from a bank folder or archive."""
MAX_FILE_BYTES = ArchiveLimits.max_file_bytes
"""The largest file an entry carries (a failure video, a trace) that is read for an export or a copy."""
MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects accepted in a sidecar."""
ENTRY_FILE_KEYS = ("video", "trace", "converted_video")
"""Provenance fields that may name one of the entry's own files by its path relative to the entry folder (a
mined failure's ``video: "failure.webm"``, its converted script's clip ``converted_video: "converted.webm"``); a
merge rewrites them to the merged copy's path."""

PathLike = Union[str, os.PathLike]


def entry_file_name(name: Any) -> str:
    """``name`` if it is a valid file name inside an entry folder (:func:`is_entry_file`), else a
    :class:`BankError` saying so."""
    if not is_entry_file(name):
        raise BankError(f"invalid entry file name {name!r}: use a relative path of letters, digits, '_', '-', "
                        f"'.' and '/' (no '..', no hidden parts, not {SCRIPT} or {SIDECAR})")
    return name


def entry_files(source: Provenance) -> List[str]:
    """The files a sidecar's ``source`` says the entry carries (:data:`ENTRY_FILES` of the source and of its
    ``merged`` records; valid relative names only), in order, without repeats."""
    lists = [list(source.files or ())] + [m.get(ENTRY_FILES) for m in source.merged or () if isinstance(m, Mapping)]
    out: List[str] = []
    for listed in lists:
        for value in listed if isinstance(listed, list) else []:
            if is_entry_file(value) and value not in out:
                out.append(value)
    return out


def unsafe_input(error: UnsafeInputError, suffix: str = "") -> UnsafeBankInputError:
    """``error`` (from :mod:`scenario_bank.safe_files`) as the bank's :class:`UnsafeBankInputError`."""
    return UnsafeBankInputError(f"{error}{suffix}")


def read_text(folder: Path, relative: str, max_bytes: int) -> str:
    """``folder/relative`` as UTF-8 text: a regular file (no part a symbolic link) of at most ``max_bytes``."""
    data = read_in_folder(folder, relative, max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise UnsafeInputError(f"{folder / relative} is not UTF-8 text ({error.reason} at byte {error.start}); "
                               "rewrite it as UTF-8") from None


def read_json(folder: Path, relative: str, max_bytes: int = MAX_SIDECAR_BYTES, shown: Optional[str] = None) -> Any:
    """``folder/relative`` parsed as JSON, size and nesting capped (:func:`load_json_bounded`); ``shown`` names
    it in errors (default: its path)."""
    return load_json_bounded(read_in_folder(folder, relative, max_bytes), MAX_JSON_DEPTH,
                             shown or str(folder / relative))


@dataclass
class ScenarioEntry:
    """One scenario of a bank: its script path and its sidecar (:class:`~scenario_bank.records.Sidecar`, read and
    checked once when the bank is listed)."""

    name: str
    folder: Path
    sidecar: Sidecar

    @property
    def script_path(self) -> Path:
        return self.folder / SCRIPT

    @property
    def script(self) -> str:
        """The Scenic source: a regular file in the entry folder (never a link), at most
        :data:`MAX_SCRIPT_BYTES`; :class:`UnsafeBankInputError` otherwise."""
        try:
            return read_text(self.folder.parent, f"{self.folder.name}/{SCRIPT}", MAX_SCRIPT_BYTES)
        except UnsafeInputError as error:
            raise unsafe_input(error) from None

    @property
    def description(self) -> str:
        return self.sidecar.description

    @property
    def elements(self) -> Elements:
        """The entry's elements (empty when its sidecar has none)."""
        return self.sidecar.elements or Elements()

    @property
    def tags(self) -> List[str]:
        return list(self.sidecar.tags)

    @property
    def map(self) -> str:
        return self.sidecar.map

    @property
    def source(self) -> Provenance:
        """Where the entry came from: its sidecar's ``source`` (:class:`~scenario_bank.records.Provenance`)."""
        return self.sidecar.provenance

    @property
    def content_hash(self) -> str:
        return self.sidecar.content_hash or ""

    @property
    def files(self) -> List[Path]:
        """Absolute paths of the files the entry carries in its folder (:func:`entry_files`), whether or not
        they exist."""
        return [self.folder / name for name in entry_files(self.source)]

    def missing_files(self) -> List[str]:
        """The entry's files (relative names, :func:`entry_files`) that are not in its folder."""
        return [name for name in entry_files(self.source)
                if not regular_file_in_folder(self.folder.parent, f"{self.folder.name}/{name}")]

    def summary(self) -> Dict[str, Any]:
        """A JSON-ready record for listings."""
        return {"name": self.name, "description": self.description, "tags": self.tags, "map": self.map,
                "source": self.source.kind, "elements": self.elements.to_dict(), "content_hash": self.content_hash,
                "path": str(self.script_path)}


def validate_sidecar(meta: Any, folder: Path) -> Sidecar:
    """Check a sidecar read from ``folder`` (its format: :class:`~scenario_bank.records.Sidecar`, which raises a
    :class:`~scenario_bank.records.RecordError` naming the field, or a :class:`BankVersionError`) and that the
    folder holds its script; return its record, its elements in canonical form."""
    record = Sidecar.from_dict(meta)
    if record.elements is None:
        record = record.replace(elements=Elements())
    if not regular_file_in_folder(folder.parent, f"{folder.name}/{SCRIPT}"):
        if os.path.lexists(folder / SCRIPT):
            raise UnsafeBankInputError(f"the script {SCRIPT} is not a regular file (a link, a FIFO or a device?); "
                            "replace it by the script itself")
        raise UnsafeBankInputError(f"the script {SCRIPT} is missing")
    return record


def _has_element(elements: Elements, wanted: str) -> bool:
    if ":" in wanted:
        who, what = wanted.split(":", 1)
        return (who, what) in elements.actions
    return (
        wanted == elements.road
        or wanted in elements.participants
        or any(a[1] == wanted for a in elements.actions)
        or any(r[1] == wanted for r in elements.relations)
    )


def _printable(name: str) -> str:
    """A folder name as it can be shown and used as a key: control and undecodable characters escaped."""
    return name.encode("unicode_escape", "backslashreplace").decode("ascii")[:200]


def _slug(text: str) -> str:
    words = re.findall(r"[a-z0-9]+", text.lower())
    stop = {"the", "a", "an", "of", "and", "in", "on", "is", "it", "its", "to", "car", "ego"}
    slug = "_".join([w for w in words if w not in stop][:6]) or "scenario"
    return slug[:60]


def _check_is_bank(root: Path, visible: Sequence[os.DirEntry]) -> None:
    """Raise :class:`NotABankError` unless ``root`` is empty or holds a bank entry."""
    if not visible:
        return
    for d in visible:
        if d.is_dir() and ((Path(d.path) / SCRIPT).exists() or (Path(d.path) / SIDECAR).exists()):
            return
    shown = ", ".join(sorted(d.name for d in visible)[:3]) + (", ..." if len(visible) > 3 else "")
    raise NotABankError(
        f"{root} is not a scenario bank: none of its subfolders holds a {SCRIPT} or {SIDECAR} "
        f"(it holds {shown}). Pass a bank folder (its entries are <name>/{SCRIPT} + <name>/{SIDECAR}), "
        "or a new or empty folder to start a bank there."
    )


def entry_matches(entry: ScenarioEntry, tag: Optional[str], needle: Optional[str], wanted: Sequence[str],
                  map_name: Optional[str], source: Optional[str]) -> bool:
    """Whether ``entry`` passes every given filter of a listing (``needle``: a lowercase substring of the name or
    description; ``wanted``: elements it must all have)."""
    sidecar = entry.sidecar
    if tag is not None and tag not in sidecar.tags:
        return False
    if map_name is not None and sidecar.map != map_name:
        return False
    if source is not None and entry.source.kind != source:
        return False
    if needle is not None and needle not in entry.name.lower() and needle not in sidecar.description.lower():
        return False
    return all(_has_element(sidecar.elements or Elements(), w) for w in wanted)


@dataclass
class Listing:
    """What :func:`scan_entries` read of a bank folder: its ``entries`` (name -> entry), the ``problems`` of the
    entries it could not load (name -> message), each entry's :func:`~scenario_bank.dedup.semantic_key`, and the
    ``index`` records to cache (name -> sidecar stamp, sidecar and semantic key)."""

    entries: Dict[str, ScenarioEntry]
    problems: Dict[str, str]
    semantic_keys: Dict[str, str]
    index: Dict[str, Any]


def scan_entries(root: Path, cached: Mapping[str, Any]) -> Listing:
    """Every entry of the bank folder ``root`` (none if it does not exist), reading a sidecar only when
    ``cached`` (an index written from an earlier :class:`Listing`) has no record of it with the same
    modification time and size. :class:`~scenario_bank.errors.NotABankError` if ``root`` is not a bank (a folder
    of other things, or a file)."""
    entries: Dict[str, ScenarioEntry] = {}
    problems: Dict[str, str] = {}
    fresh: Dict[str, Any] = {}
    keys: Dict[str, str] = {}
    if root.exists() and not root.is_dir():
        raise NotABankError(f"{root} is not a scenario bank: it is a file, not a folder. Pass a bank folder, or a new "
                            "or empty folder to start a bank there.")
    if root.is_dir():
        with os.scandir(root) as it:
            visible = [d for d in it if not d.name.startswith(".")]
        _check_is_bank(root, visible)
        for d in sorted(visible, key=lambda d: d.name):
            name = d.name
            if d.is_symlink():
                if d.is_dir():
                    problems[_printable(name)] = (
                        f"{_printable(name)} is a symbolic link to a folder; bank entries must be real folders "
                        "inside the bank: replace the link by a copy of the entry")
                continue
            if not d.is_dir(follow_symlinks=False):
                continue
            if not is_entry_name(name):
                problems[_printable(name)] = (
                    f"the folder name {_printable(name)!r} is not a valid entry name (1 to 128 letters, digits, "
                    "'_', '-' and '.', not starting with '.' or '-', no '..'); rename the folder")
                continue
            folder = root / name
            try:
                st = os.lstat(folder / SIDECAR)
            except FileNotFoundError:
                problems[name] = f"missing sidecar {name}/{SIDECAR}: re-add the scenario or restore the file"
                continue
            except OSError as error:
                problems[name] = f"unreadable sidecar {name}/{SIDECAR}: {error.strerror or error}"
                continue
            stamp = [st.st_mtime_ns, st.st_size]
            hit = cached.get(name)
            sidecar: Optional[Sidecar] = None
            if stat.S_ISREG(st.st_mode) and isinstance(hit, dict) and hit.get("stamp") == stamp \
                    and "semantic_key" in hit:
                meta, key = hit.get("meta"), hit["semantic_key"]
                if isinstance(meta, dict) and isinstance(meta.get("source"), dict):
                    sidecar = Sidecar.from_checked(meta)  # the index holds sidecars read and checked before
            if sidecar is None:
                try:
                    sidecar = validate_sidecar(read_json(root, f"{name}/{SIDECAR}"), folder)
                    key = semantic_key(sidecar.elements, sidecar.map,
                                       read_text(root, f"{name}/{SCRIPT}", MAX_SCRIPT_BYTES))
                except (ValueError, BankVersionError, OSError) as error:
                    problems[name] = f"bad sidecar {name}/{SIDECAR}: {error}"
                    continue
                meta = sidecar.to_dict()
            fresh[name] = {"stamp": stamp, "meta": meta, "semantic_key": key}
            entries[name] = ScenarioEntry(name, folder, sidecar)
            keys[name] = key
    return Listing(entries, problems, keys, fresh)


def entry_bytes(root: Path, entry: ScenarioEntry) -> List[Tuple[str, bytes]]:
    """``(relative path, bytes)`` of an entry's script, sidecar and the files it lists that exist, each read
    as a capped regular file with no part a link (:func:`~scenario_bank.safe_files.read_in_folder`)."""
    out = [(SCRIPT, read_in_folder(root, f"{entry.name}/{SCRIPT}", MAX_SCRIPT_BYTES)),
           (SIDECAR, read_in_folder(root, f"{entry.name}/{SIDECAR}", MAX_SIDECAR_BYTES))]
    for file in entry_files(entry.source):
        if regular_file_in_folder(root, f"{entry.name}/{file}"):
            out.append((file, read_in_folder(root, f"{entry.name}/{file}", MAX_FILE_BYTES)))
    return out


def new_sidecar(script: str, description: str, name: Optional[str],
                elements: Union[None, Elements, Mapping[str, Any]],
                tags: Sequence[str], map_name: Optional[str],
                provenance: Union[None, Provenance, Mapping[str, Any]], use_case: Optional[str]) -> Sidecar:
    """The sidecar of a new entry, checked (:class:`~scenario_bank.errors.BankError` naming what is wrong): the
    map read from ``param map`` when not given, the name made from the description when not given, the
    provenance completed (:data:`PROVENANCE_FIELDS`, and :data:`MINED_PROVENANCE_FIELDS` for a mined entry;
    ``kind`` hand-written and ``date`` today by default: :func:`new_provenance`)."""
    if not isinstance(script, str) or not script.strip():
        raise BankError("the script is empty")
    if not description or not description.strip():
        raise BankError("a scenario needs a natural-language description")
    if map_name is None:
        match = re.search(r"^\s*param\s+map\s*=\s*['\"]([^'\"]+)['\"]", script, re.M)
        map_name = Path(match.group(1)).stem if match else None
    if not map_name:
        raise BankError("could not tell the scenario's map: pass map=... or set `param map = '<name>'`")
    name = name or _slug(description)
    if not NEW_ENTRY_NAME.match(name):
        raise BankError(f"invalid scenario name {name!r}: use lowercase letters, digits, '_' or '-'")
    try:
        elements = Elements.from_dict(elements or {})
    except ElementError as error:
        raise BankError(f"invalid elements: {error}") from None
    source = new_provenance(provenance)
    meta = Sidecar(
        schema_version=SIDECAR_VERSION, name=name, description=description.strip(), elements=elements,
        tags=tuple(sorted(set(tags))), map=map_name, use_case=use_case, source=source,
        content_hash=content_hash(script),
    )
    field_name = control_character_field(meta.to_dict())
    if field_name is not None:
        raise BankError(f"the scenario's {field_name} holds a control character: {CONTROL_FIX}")
    return meta


def new_provenance(provenance: Union[None, Provenance, Mapping[str, Any]]) -> Provenance:
    """The provenance of a new entry, checked (:class:`~scenario_bank.errors.BankError` naming a bad field) and
    completed: every :data:`PROVENANCE_FIELDS` written (``null`` when unknown), a mined entry's
    :data:`MINED_PROVENANCE_FIELDS` too, ``kind`` hand-written and ``date`` today by default."""
    given = provenance.to_dict() if isinstance(provenance, Provenance) else dict(provenance or {})
    for key in ("kind", "date"):
        if not given.get(key):
            given.pop(key, None)
    try:
        record = Provenance.from_dict(given)
    except RecordError as error:
        raise BankError(str(error)) from None
    record = record.replace(kind=record.kind or "hand-written", date=record.date or _dt.date.today().isoformat())
    return record.replace(null_fields=record.null_fields | Provenance(kind=given.get("kind")).default_null_fields())
