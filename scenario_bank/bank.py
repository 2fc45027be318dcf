"""The scenario bank: a versioned, validated, searchable folder of Scenic scenarios.

Layout of a bank folder::

    <name>/scenario.scenic    the Scenic script
    <name>/meta.json          its sidecar (description, elements, tags, map, source, hash)

A folder is a bank when at least one of its subfolders holds a ``scenario.scenic``
or a ``meta.json``; a missing or empty folder is a new, empty bank. Any other
folder is refused (:class:`NotABankError`) rather than read as broken entries.

Nothing but entries and the writers' lock file (the hidden ``.dv2s-writers.lock``, created
by the first write) is written into the bank folder: the index (a cache of every entry's
metadata) lives in the user cache directory (:mod:`scenario_bank.cache`, one folder per
bank, keyed by its path), so a read-only bank (e.g. the one shipped inside an installed
package) is fully usable for reading. The lock lives beside the entries so that every writer
of a bank takes the same lock, whatever its user, cache directory or host (on a shared
file system whose ``flock`` is honoured across clients, as NFSv4's is on Linux).

Writes are atomic: an entry is assembled in a hidden staging folder and renamed
into place in one step, so a crash or a full disk leaves either the whole entry
or nothing. Imports of several entries keep a journal and are rolled back if
they did not finish. Concurrent writers serialise on the lock; readers never
block. The index is rebuilt from the sidecars whenever it is stale, and a
missing, corrupt or hand-edited sidecar is reported for that entry while the
rest of the bank stays usable.

Bank folders and archives may come from anyone: every file of a bank is read through
:mod:`scenario_bank.safe_files` (regular files only, never through a link, size-capped, JSON depth-capped),
every name read from a folder, an archive or a sidecar is checked against one safe pattern, and an
archive is streamed into a private folder under caps before anything of it is used.

This module imports nothing else of dv2s-gym.
"""

from __future__ import annotations

import ast
import datetime as _dt
import difflib
import errno
import fcntl
import hashlib
import io
import json
import lzma
import os
import random
import re
import shutil
import stat
import tarfile
import tempfile
import unicodedata
import uuid
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

from scenario_bank.atomic import atomic_path, atomic_write_json, atomic_write_text
from scenario_bank.cache import keyed_cache_dir
from scenario_bank.elements import ElementError, normalize_elements
from scenario_bank.errors import DV2SError
from scenario_bank.safe_files import (ArchiveLimits, UnsafeInputError, extract_archive, is_entry_name,
                                      load_json_bounded, read_in_folder, read_regular_file, real_folder_in,
                                      regular_file_in_folder, validate_entry_name, validate_relative_path)
from scenario_bank.safety import UnsafeScenarioError
from scenario_bank.sandbox import SandboxError, verify_script

BANK_DIR = Path(__file__).resolve().parent / "scenarios"
"""Folder of the bank shipped with dv2s-gym."""

__all__ = [
    "BANK_DIR",
    "BANK_VERSION",
    "SIDECAR_VERSION",
    "Bank",
    "ScenarioEntry",
    "BankDiff",
    "BankError",
    "BankVersionError",
    "UnsafeBankInputError",
    "ArchiveLimits",
    "MAX_SCRIPT_BYTES",
    "MAX_SIDECAR_BYTES",
    "MAX_FILE_BYTES",
    "DuplicateScenarioError",
    "NotABankError",
    "ScenarioRejectedError",
    "UnknownScenarioError",
    "content_hash",
    "semantic_key",
    "SOURCE_KINDS",
    "MINED_PROVENANCE_FIELDS",
    "AddOutcome",
    "param_ranges",
    "near_duplicate",
    "changed_code_lines",
    "NEAR_COPY_LINES",
    "ENTRY_FILE_KEYS",
    "ENTRY_FILES",
    "entry_files",
    "entry_file_name",
]

BANK_VERSION = 1
"""Version of the bank folder format written by this code."""
SIDECAR_VERSION = 1
"""Version of the ``meta.json`` sidecar format written by this code."""
SOURCE_KINDS = ("hand-written", "generated", "mined")
SCRIPT = "scenario.scenic"
SIDECAR = "meta.json"
INDEX = "index.json"
LEGACY_INDEX = "bank.json"  # written into the bank folder by dv2s-gym <= 0.1.0; still marks a bank
WRITERS_LOCK = ".dv2s-writers.lock"
"""The file writers of a bank lock (``flock``), in the bank folder itself."""
_NAME = re.compile(r"^[a-z0-9][a-z0-9_\-]{0,99}$")
"""Names of new entries; an existing folder or an archive entry only needs a safe name (:func:`is_entry_name`)."""
MAX_SCRIPT_BYTES = ArchiveLimits.max_script_bytes
"""The largest ``scenario.scenic`` read from a bank folder or archive."""
MAX_SIDECAR_BYTES = ArchiveLimits.max_sidecar_bytes
"""The largest ``meta.json`` (or archive header) read from a bank folder or archive."""
MAX_FILE_BYTES = ArchiveLimits.max_file_bytes
"""The largest file an entry carries (a failure video, a trace) that is read for an export or a copy."""
MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects accepted in a sidecar."""
_MAX_INDEX_BYTES = 256 << 20
ARCHIVE_HEADER = "bank-archive.json"
_PROVENANCE_FIELDS = ("kind", "video", "parent", "seed", "generator", "model", "context_hash", "date")
MINED_PROVENANCE_FIELDS = ("params", "backends", "policy", "failure", "cluster", "reproduction", "e2e_sc", "run", "trace",
                           "index", "merged", "interaction", "judge", "replay", "replay_entry", "converted")
"""Extra provenance of ``kind == "mined"`` entries (failure mining): the parent's sampled parameters, the
DRA/SG backends, the policy that failed, its failure and cluster, the reproduction rate and E2E-SC, the
mining run and episode index, ``merged``: later failures merged into this entry (see
:meth:`Bank.add_or_merge`), ``interaction``: the failure's actor and manoeuvre read from its trace,
``judge``: the checks the converted script passed, ``replay``: on an exact replay of the failing scene,
the parameters, seed and trajectory hash that pin it, and the links between the two entries of one failure
(``replay_entry`` on the converted script, ``converted`` on the replay). Sidecars without them (every older
sidecar) load as before."""

ENTRY_FILE_KEYS = ("video", "trace")
"""Provenance fields that may name one of the entry's own files by its path relative to the entry folder (a
mined failure's ``video: "failure.webm"``); a merge rewrites them to the merged copy's path."""
ENTRY_FILES = "files"
"""The provenance field listing the files an entry carries in its own folder (relative paths), in ``source``
and in each ``source.merged`` record. They are added with the entry (``files=`` of :meth:`Bank.add` /
:meth:`Bank.add_or_merge`), travel with :meth:`Bank.export`, :meth:`Bank.import_archive` and
:meth:`Bank.copy_to`, and ``dv2s bank validate`` reports one that is missing. Older sidecars have none."""
_ENTRY_FILE = re.compile(r"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]*(/[A-Za-z0-9_\-][A-Za-z0-9_.\-]*)*$")

PathLike = Union[str, os.PathLike]


def _is_entry_file(name: Any) -> bool:
    """Whether ``name`` is a valid file name inside an entry folder (relative, at most 8 parts each a safe
    name (:func:`~scenario_bank.safe_files.validate_relative_path`), no hidden parts, not the script or sidecar)."""
    if not (isinstance(name, str) and bool(_ENTRY_FILE.match(name)) and name not in (SCRIPT, SIDECAR)):
        return False
    try:
        validate_relative_path(name)
    except UnsafeInputError:
        return False
    return True


def entry_file_name(name: Any) -> str:
    """``name`` if it is a valid file name inside an entry folder (:func:`_is_entry_file`), else a
    :class:`BankError` saying so."""
    if not _is_entry_file(name):
        raise BankError(f"invalid entry file name {name!r}: use a relative path of letters, digits, '_', '-', "
                        f"'.' and '/' (no '..', no hidden parts, not {SCRIPT} or {SIDECAR})")
    return name


def entry_files(source: Mapping[str, Any]) -> List[str]:
    """The files a sidecar's ``source`` says the entry carries (:data:`ENTRY_FILES` of the source and of its
    ``merged`` records; valid relative names only), in order, without repeats."""
    records = [source] + [m for m in (source.get("merged") or []) if isinstance(m, Mapping)]
    out: List[str] = []
    for record in records:
        listed = record.get(ENTRY_FILES)
        for value in listed if isinstance(listed, list) else []:
            if _is_entry_file(value) and value not in out:
                out.append(value)
    return out


class BankError(DV2SError):
    """A bank operation failed; the bank is unchanged."""


class BankVersionError(BankError):
    """The bank (or an entry) was written by a newer dv2s-gym."""


class UnsafeBankInputError(BankError, ValueError):
    """A bank folder, file, name or archive is malformed or hostile (a link, a FIFO, an unsafe name, too
    large or too deeply nested); the message names it and the fix, and nothing was written."""


def _unsafe(error: UnsafeInputError, suffix: str = "") -> UnsafeBankInputError:
    return UnsafeBankInputError(f"{error}{suffix}")


def _read_text(folder: Path, relative: str, max_bytes: int) -> str:
    """``folder/relative`` as UTF-8 text: a regular file (no part a symbolic link) of at most ``max_bytes``."""
    data = read_in_folder(folder, relative, max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise UnsafeInputError(f"{folder / relative} is not UTF-8 text ({error.reason} at byte {error.start}); "
                               "rewrite it as UTF-8") from None


def _read_json(folder: Path, relative: str, max_bytes: int = MAX_SIDECAR_BYTES, shown: Optional[str] = None) -> Any:
    """``folder/relative`` parsed as JSON, size and nesting capped (:func:`load_json_bounded`); ``shown`` names
    it in errors (default: its path)."""
    return load_json_bounded(read_in_folder(folder, relative, max_bytes), MAX_JSON_DEPTH,
                             shown or str(folder / relative))


class NotABankError(BankError, ValueError):
    """The folder holds other things than scenario entries."""


class DuplicateScenarioError(BankError):
    """The script is already in the bank (byte for byte or semantically)."""

    def __init__(self, message: str, existing: str) -> None:
        super().__init__(message)
        self.existing = existing


class ScenarioRejectedError(BankError, ValueError):
    """The script failed verification: the safety check (``stage == "safety"``, ``findings``) or its
    compile, sample and run in the sandbox (``stage``; ``limit`` when a resource limit stopped it)."""

    def __init__(self, message: str, stage: str, findings: Sequence[Any] = (), limit: Optional[str] = None) -> None:
        super().__init__(message)
        self.stage, self.findings, self.limit = stage, list(findings), limit


def verify(script: str, label: str) -> None:
    """Safety-check, compile, sample and run ``script`` once in the sandbox; raise
    :class:`ScenarioRejectedError` naming the problem. Passes are cached by content and code version."""
    try:
        verify_script(script, name=label)
    except UnsafeScenarioError as error:
        raise ScenarioRejectedError(f"not added: {error}", "safety", findings=error.findings) from None
    except SandboxError as error:
        raise ScenarioRejectedError(f"not added: {error}", error.stage, limit=error.limit) from None


def _upgrade_scenic2(script: str, provenance: Optional[Mapping[str, Any]],
                     upgrade: bool) -> Tuple[str, Optional[Mapping[str, Any]]]:
    """``script`` upgraded from Scenic 2 when ``upgrade`` is asked, its rewrites and notes added to ``provenance``."""
    if not upgrade or not isinstance(script, str):
        return script, provenance
    from scenario_bank.scenic2 import upgrade_scenic2

    result = upgrade_scenic2(script)
    if not result.changed:
        return script, provenance
    provenance = dict(provenance or {})
    provenance["scenic2_rewrites"] = [str(r) for r in result.rewrites]
    provenance["scenic2_notes"] = list(result.notes)
    return result.source, provenance


def _verify_or_name_scenic2(script: str, label: str, upgraded: bool) -> None:
    """:func:`verify`; a refused script in Scenic 2 syntax (not upgraded) gets an error naming the construct."""
    try:
        verify(script, label)
    except ScenarioRejectedError as error:
        if not upgraded:
            from scenario_bank.scenic2 import looks_like_scenic2, upgrade_scenic2

            if looks_like_scenic2(script, str(error)):
                first = upgrade_scenic2(script, keep_scenic2_meaning=False).rewrites[0]  # refused in 3
                raise ScenarioRejectedError(
                    f"not added: {label} is Scenic 2: line {first.line}: `{first.before.strip()[:80]}` ({first.why}); "
                    "pass upgrade_scenic2=True to Bank.add to upgrade it to Scenic 3 (each rewrite is recorded in "
                    "the entry's provenance; `dv2s bank add` does this)", error.stage, findings=error.findings,
                    limit=error.limit) from None
        raise


class UnknownScenarioError(BankError, ValueError):
    """A scenario name or tag that the bank does not hold."""


def content_hash(script: str) -> str:
    """SHA-256 of a script's UTF-8 bytes (the sidecar's ``content_hash``)."""
    return hashlib.sha256(script.encode("utf-8")).hexdigest()


_PARAM = re.compile(r"^\s*param\s+(\w+)\s*=\s*(.+?)\s*$", re.M)
_RANDOM = re.compile(r"\b(Range|DiscreteRange|Uniform|Discrete|Normal|TruncatedNormal|Options|VerifaiRange|"
                     r"VerifaiDiscreteRange|VerifaiOptions)\s*\(")


def semantic_key(elements: Mapping[str, Any], map_name: Optional[str], script: str) -> str:
    """What makes two scenarios the same: elements, map and the multiset of parameter ranges."""
    ranges = sorted(re.sub(r"\s+", "", value) for name, value in _PARAM.findall(script)
                    if name not in ("map", "weather") and _RANDOM.search(value))
    payload = json.dumps([normalize_elements(elements), map_name, ranges], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


_RANGE_CALLS = ("Range", "DiscreteRange", "VerifaiRange", "VerifaiDiscreteRange", "Uniform", "Options",
                "Discrete", "VerifaiOptions")


def _numeric_interval(node: ast.AST) -> Optional[Tuple[float, float]]:
    """``(low, high)`` a Scenic parameter expression ranges over, for the numeric forms only."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value), float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _numeric_interval(node.operand)
        if inner is None:
            return None
        return (-inner[1], -inner[0]) if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _RANGE_CALLS \
            and node.args and not node.keywords:
        bounds = [_numeric_interval(arg) for arg in node.args]
        if any(b is None for b in bounds):
            return None
        if node.func.id in ("Range", "DiscreteRange", "VerifaiRange", "VerifaiDiscreteRange") and len(bounds) != 2:
            return None
        return min(b[0] for b in bounds), max(b[1] for b in bounds)
    return None


def param_ranges(script: str) -> Dict[str, Tuple[float, float]]:
    """The numeric global parameters of a script (``param x = Range(a, b)``, ``-Range(...)``, a number,
    ``Uniform``/``Options`` of numbers) as ``name -> (low, high)``; other parameters are left out."""
    out: Dict[str, Tuple[float, float]] = {}
    for name, value in _PARAM.findall(script):
        try:
            tree = ast.parse(value.split("#", 1)[0].strip(), mode="eval")
        except SyntaxError:
            continue
        interval = _numeric_interval(tree.body)
        if interval is not None:
            out[name] = interval
    return out


def near_duplicate(elements_a: Mapping[str, Any], map_a: Optional[str], script_a: str,
                   elements_b: Mapping[str, Any], map_b: Optional[str], script_b: str) -> bool:
    """Whether two scenarios are near-duplicates: the same map, the same elements (canonical form) and
    every numeric parameter both scripts define ranging over overlapping intervals."""
    if map_a != map_b or normalize_elements(elements_a) != normalize_elements(elements_b):
        return False
    ranges_a, ranges_b = param_ranges(script_a), param_ranges(script_b)
    return all(ranges_a[p][0] <= ranges_b[p][1] and ranges_b[p][0] <= ranges_a[p][1]
               for p in set(ranges_a) & set(ranges_b))


NEAR_COPY_LINES = 2
"""Two scripts whose code (comments and blank lines aside) differs in at most this many lines are near-copies
(:func:`changed_code_lines`)."""


def _code_lines(script: str) -> List[str]:
    lines: List[str] = []
    for line in script.splitlines():
        text = line.strip()
        if not text or text.startswith("#") or (not lines and text.startswith(('"' * 3, "'" * 3))):
            continue
        lines.append(text)
    return lines


def changed_code_lines(script_a: str, script_b: str) -> int:
    """How many lines of code (blank lines, comment lines and a leading one-line docstring aside) one script would
    need changed, added or removed to become the other."""
    a, b = _code_lines(script_a), _code_lines(script_b)
    matcher = difflib.SequenceMatcher(None, a, b, autojunk=False)
    return sum(max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in matcher.get_opcodes() if tag != "equal")


@dataclass
class AddOutcome:
    """What :meth:`Bank.add_or_merge` did: ``status`` "added" (a new ``entry``) or "merged" (the
    provenance was appended to the existing ``entry``'s ``source.merged``; ``how`` says why)."""

    status: str
    entry: "ScenarioEntry"
    how: Optional[str] = None


@dataclass
class ScenarioEntry:
    """One scenario of a bank: its script path and its sidecar."""

    name: str
    folder: Path
    meta: Dict[str, Any]

    @property
    def script_path(self) -> Path:
        return self.folder / SCRIPT

    @property
    def script(self) -> str:
        """The Scenic source: a regular file in the entry folder (never a link), at most
        :data:`MAX_SCRIPT_BYTES`; :class:`UnsafeBankInputError` otherwise."""
        try:
            return _read_text(self.folder.parent, f"{self.folder.name}/{SCRIPT}", MAX_SCRIPT_BYTES)
        except UnsafeInputError as error:
            raise _unsafe(error) from None

    @property
    def description(self) -> str:
        return self.meta.get("description", "")

    @property
    def elements(self) -> Dict[str, Any]:
        return self.meta.get("elements") or {"road": None, "participants": [], "actions": [], "relations": []}

    @property
    def tags(self) -> List[str]:
        return list(self.meta.get("tags", []))

    @property
    def map(self) -> Optional[str]:
        return self.meta.get("map")

    @property
    def source(self) -> Dict[str, Any]:
        return dict(self.meta.get("source") or {})

    @property
    def content_hash(self) -> str:
        return self.meta.get("content_hash", "")

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
                "source": self.source.get("kind"), "elements": self.elements, "content_hash": self.content_hash,
                "path": str(self.script_path)}


@dataclass
class BankDiff:
    """Differences between two banks, by entry name."""

    only_in_first: List[str] = field(default_factory=list)
    only_in_second: List[str] = field(default_factory=list)
    changed: List[str] = field(default_factory=list)
    same: List[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return not (self.only_in_first or self.only_in_second or self.changed)


def _control_character_field(value: Any, where: str = "") -> Optional[str]:
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
        found = _control_character_field(item, f"{where}{key}" if key.startswith("[") or not where else f"{where}.{key}")
        if found is not None:
            return found
    return None


_CONTROL_FIX = ("control characters (escape sequences, carriage returns, ...) are not allowed in a bank "
                "entry's description, tags or other sidecar text; remove them")


def _validate_sidecar(meta: Any, folder: Path) -> Dict[str, Any]:
    """Check a sidecar; return it or raise ``ValueError`` saying what is wrong."""
    if not isinstance(meta, dict):
        raise ValueError("sidecar is not a JSON object")
    field_name = _control_character_field(meta)
    if field_name is not None:
        raise ValueError(f"sidecar field {field_name!r} holds a control character: {_CONTROL_FIX}")
    version = meta.get("schema_version", 1)
    if not isinstance(version, int) or version > SIDECAR_VERSION:
        raise BankVersionError(
            f"sidecar schema_version {version!r} is newer than this dv2s-gym supports ({SIDECAR_VERSION}); upgrade"
        )
    for key in ("description", "map"):
        if not isinstance(meta.get(key), str) or not meta.get(key):
            raise ValueError(f"sidecar field {key!r} is missing or not a non-empty string")
    if not isinstance(meta.get("tags", []), list) or not all(isinstance(t, str) for t in meta.get("tags", [])):
        raise ValueError("sidecar field 'tags' must be a list of strings")
    try:
        meta["elements"] = normalize_elements(meta.get("elements") or {})
    except ElementError as error:
        raise ValueError(f"sidecar elements: {error}") from None
    source = meta.get("source") or {}
    if source.get("kind") not in SOURCE_KINDS:
        raise ValueError(f"sidecar source.kind must be one of {SOURCE_KINDS}, got {source.get('kind')!r}")
    merged = source.get("merged")
    if merged is not None and not (isinstance(merged, list) and all(isinstance(m, dict) for m in merged)):
        raise ValueError("sidecar field 'source.merged' must be a list of objects (merged failures)")
    if "name" in meta and not is_entry_name(meta["name"]):
        raise ValueError(f"sidecar field 'name' {str(meta['name'])[:80]!r} is not a valid entry name; "
                         "set it to the entry folder's name")
    for where, record in [("source", source)] + [(f"source.merged[{k}]", m) for k, m in enumerate(merged or [])]:
        listed = record.get(ENTRY_FILES)
        if listed is None:
            continue
        if not isinstance(listed, list):
            raise ValueError(f"sidecar field '{where}.{ENTRY_FILES}' must be a list of file names in the entry folder")
        for file in listed:
            if not _is_entry_file(file):
                raise ValueError(f"sidecar field '{where}.{ENTRY_FILES}' names {str(file)[:80]!r}, which is not a "
                                 "file inside the entry folder: list relative paths of letters, digits, '_', '-', "
                                 "'.' and '/' only (no '..', not absolute)")
    if not regular_file_in_folder(folder.parent, f"{folder.name}/{SCRIPT}"):
        if os.path.lexists(folder / SCRIPT):
            raise ValueError(f"the script {SCRIPT} is not a regular file (a link, a FIFO or a device?); "
                             "replace it by the script itself")
        raise ValueError(f"the script {SCRIPT} is missing")
    return meta


class Bank:
    """A scenario bank folder. ``Bank()`` opens the bank shipped with dv2s-gym.

    Args:
        root: the bank folder (created on first write if it does not exist).
    """

    def __init__(self, root: Optional[PathLike] = None) -> None:
        self.root = Path(root) if root is not None else BANK_DIR
        self.read_only = root is None
        """The shipped bank (opened without a folder) is part of the installed package: never written."""
        self._entries: Dict[str, ScenarioEntry] = {}
        self.problems: Dict[str, str] = {}
        """Entries that could not be loaded, with the reason (name -> message)."""
        self._load()

    @classmethod
    def open(cls, root: Optional[PathLike] = None) -> "Bank":
        """Open a bank folder (the shipped bank by default)."""
        return cls(root)

    # ------------------------------------------------------------- loading
    def _cache_folder(self) -> Path:
        """This bank's folder in the user cache (its index)."""
        return keyed_cache_dir("banks", self.root)

    def _read_index(self) -> Dict[str, Any]:
        legacy = self.root / LEGACY_INDEX
        if os.path.lexists(legacy):  # the folder's own format version, as written by dv2s-gym <= 0.1.0
            try:
                version = _read_json(self.root, LEGACY_INDEX, _MAX_INDEX_BYTES).get("version", 0)
            except (OSError, ValueError, AttributeError):
                version = 0
            if not isinstance(version, int) or version > BANK_VERSION:
                raise BankVersionError(
                    f"the bank at {self.root} has format version {version!r}, newer than this dv2s-gym "
                    f"supports ({BANK_VERSION}); upgrade dv2s-gym to read it"
                )
        try:
            index_path = self._cache_folder() / INDEX
        except OSError:
            return {"version": BANK_VERSION, "entries": {}}  # no usable cache: read the sidecars
        if not index_path.is_file():
            return {"version": BANK_VERSION, "entries": {}}
        try:
            index = load_json_bounded(read_regular_file(index_path, _MAX_INDEX_BYTES), MAX_JSON_DEPTH, str(index_path))
        except (OSError, ValueError):
            return {"version": BANK_VERSION, "entries": {}}  # rebuilt from sidecars below
        if not isinstance(index, dict) or index.get("version") != BANK_VERSION:
            return {"version": BANK_VERSION, "entries": {}}  # another dv2s-gym's cache: rebuilt below
        return index

    def _load(self, locked: bool = False) -> None:
        index = self._read_index()
        if locked:
            self._clean_up()
        elif self.root.is_dir() and any(self.root.glob(".journal-*.json")) and os.access(self.root, os.W_OK):
            with self._lock():
                self._clean_up()
        cached: Dict[str, Any] = index.get("entries", {})
        entries: Dict[str, ScenarioEntry] = {}
        problems: Dict[str, str] = {}
        fresh: Dict[str, Any] = {}
        self._semantic_keys: Dict[str, str] = {}
        if self.root.is_dir():
            with os.scandir(self.root) as it:
                visible = [d for d in it if not d.name.startswith(".")]
            _check_is_bank(self.root, visible)
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
                folder = self.root / name
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
                if stat.S_ISREG(st.st_mode) and isinstance(hit, dict) and hit.get("stamp") == stamp \
                        and "semantic_key" in hit:
                    meta, key = hit["meta"], hit["semantic_key"]
                else:
                    try:
                        meta = _validate_sidecar(_read_json(self.root, f"{name}/{SIDECAR}"), folder)
                        key = semantic_key(meta["elements"], meta["map"],
                                           _read_text(self.root, f"{name}/{SCRIPT}", MAX_SCRIPT_BYTES))
                    except (ValueError, BankVersionError, OSError) as error:
                        problems[name] = f"bad sidecar {name}/{SIDECAR}: {error}"
                        continue
                fresh[name] = {"stamp": stamp, "meta": meta, "semantic_key": key}
                entries[name] = ScenarioEntry(name, folder, meta)
                self._semantic_keys[name] = key
        self._entries, self.problems = entries, problems
        if fresh != cached and self.root.is_dir():
            try:
                self._write_json_atomic(self._cache_folder() / INDEX,
                                        {"version": BANK_VERSION, "root": str(self.root.resolve()), "entries": fresh})
            except OSError:
                pass  # the index is only a cache

    def reload(self) -> None:
        """Re-read the folder (other processes may have written)."""
        self._load()

    # ------------------------------------------------------------- reading
    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, name: str) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[ScenarioEntry]:
        return iter(self._entries.values())

    def names(self) -> List[str]:
        """Entry names, sorted."""
        return sorted(self._entries)

    def get(self, name: str) -> ScenarioEntry:
        """One entry; :class:`UnknownScenarioError` with near matches if absent, or naming the rule if
        ``name`` is not a valid entry name."""
        if name in self._entries:
            return self._entries[name]
        if name in self.problems:
            raise UnknownScenarioError(f"scenario {name!r} is unusable: {self.problems[name]}")
        if not is_entry_name(name):
            try:
                validate_entry_name(name, "scenario name")
            except UnsafeInputError as error:
                raise UnknownScenarioError(f"{error}. `dv2s bank list` shows the bank's scenarios") from None
        near = difflib.get_close_matches(name, self._entries, n=3, cutoff=0.5)
        hint = f" Did you mean {', '.join(repr(n) for n in near)}?" if near else ""
        raise UnknownScenarioError(
            f"unknown scenario {name!r}.{hint} The bank at {self.root} holds {len(self)} scenarios "
            "(`dv2s bank list`). Pass a bank name, a path to a .scenic file, Scenic source text, or 'tag:<tag>'."
        )

    def list(
        self,
        tag: Optional[str] = None,
        text: Optional[str] = None,
        element: Optional[Union[str, Sequence[str]]] = None,
        map: Optional[str] = None,
        source: Optional[str] = None,
    ) -> List[ScenarioEntry]:
        """Entries matching every given filter, sorted by name.

        ``text`` is a case-insensitive substring of the name or description;
        ``element`` a participant (``"pedestrian"``), an action (``"cut_in"`` or
        ``"car:cut_in"``), a relation (``"oncoming"``) or a road type.
        """
        wanted = [element] if isinstance(element, str) else list(element or [])
        needle = text.lower() if text else None
        out = []
        for name in sorted(self._entries):
            entry = self._entries[name]
            if tag is not None and tag not in entry.meta.get("tags", ()):
                continue
            if map is not None and entry.meta.get("map") != map:
                continue
            if source is not None and (entry.meta.get("source") or {}).get("kind") != source:
                continue
            if needle is not None and needle not in name.lower() and needle not in entry.meta.get("description", "").lower():
                continue
            if wanted and not all(_has_element(entry.meta.get("elements") or {}, w) for w in wanted):
                continue
            out.append(entry)
        return out

    def tags(self) -> List[str]:
        """Every tag in the bank."""
        return sorted({t for e in self._entries.values() for t in e.meta.get("tags", ())})

    def sample(
        self,
        rng: Union[None, int, random.Random] = None,
        weights: Union[None, Mapping[str, float], Callable[[ScenarioEntry], float]] = None,
        candidates: Optional[Iterable[str]] = None,
    ) -> ScenarioEntry:
        """Draw one entry, uniformly or by ``weights`` (a name->weight map or a function of the entry)."""
        names = sorted(candidates) if candidates is not None else self.names()
        if not names:
            unusable = "".join(f"; {name} is unusable: {message}" for name, message in sorted(self.problems.items())[:3])
            raise BankError(f"the bank at {self.root} holds no scenarios to sample{unusable}")
        if not isinstance(rng, random.Random):
            rng = random.Random(rng)
        if weights is None:
            w = [1.0] * len(names)
        elif callable(weights):
            w = [float(weights(self.get(n))) for n in names]
        else:
            w = [float(weights.get(n, 0.0)) for n in names]
        if any(x < 0 for x in w) or sum(w) <= 0:
            raise BankError("sampling weights must be non-negative with a positive sum")
        return self.get(rng.choices(names, weights=w, k=1)[0])

    def stats(self) -> Dict[str, Any]:
        """Counts by map, tag, source kind, road type and participant."""
        def count(values: Iterable[str]) -> Dict[str, int]:
            out: Dict[str, int] = {}
            for v in values:
                out[v] = out.get(v, 0) + 1
            return dict(sorted(out.items()))

        entries = list(self._entries.values())
        return {
            "root": str(self.root),
            "version": BANK_VERSION,
            "scenarios": len(entries),
            "problems": len(self.problems),
            "by_map": count(e.map or "?" for e in entries),
            "by_source": count(e.source.get("kind", "?") for e in entries),
            "by_road": count(e.elements.get("road") or "?" for e in entries),
            "by_tag": count(t for e in entries for t in e.tags),
            "by_participant": count(p for e in entries for p in set(e.elements.get("participants", []))),
        }

    def find_duplicate(self, script: str, elements: Optional[Mapping[str, Any]], map_name: Optional[str]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of an entry identical to this script, or ``None``."""
        digest = content_hash(script)
        for entry in self._entries.values():
            if entry.content_hash == digest:
                return entry.name, "byte-for-byte identical"
        if elements is not None:
            key = semantic_key(elements, map_name, script)
            for name, other in self._semantic_keys.items():
                if other == key:
                    return name, "semantically identical (same elements, map and parameter ranges)"
        return None

    # ------------------------------------------------------------- writing
    @contextmanager
    def _lock(self) -> Iterator[None]:
        created = not self.root.exists()
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            handle = open(self.root / WRITERS_LOCK, "a+")
        except OSError as error:
            raise _write_error(error, self.root) from None
        with handle:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
            try:
                yield
            except BaseException:
                if created:
                    self._remove_if_only_the_lock()
                raise
            finally:
                fcntl.flock(handle.fileno(), fcntl.LOCK_UN)

    def _remove_if_only_the_lock(self) -> None:
        """A write that failed into a bank folder it created leaves no folder holding only the lock file."""
        try:
            if [p.name for p in self.root.iterdir()] == [WRITERS_LOCK]:
                (self.root / WRITERS_LOCK).unlink()
                self.root.rmdir()
        except OSError:
            pass  # a writer of another process got in: the folder is its bank now

    @staticmethod
    def _write_json_atomic(path: Path, data: Any) -> None:
        atomic_write_json(path, data)

    def _stage_entry(self, name: str, script: str, meta: Dict[str, Any],
                     files: Optional[Mapping[str, PathLike]] = None) -> Path:
        field_name = _control_character_field(meta)
        if field_name is not None:  # every write passes here, whatever built the sidecar
            raise BankError(f"the sidecar field {field_name!r} of {name} holds a control character: {_CONTROL_FIX}")
        staging = self.root / f".staging-{name}-{uuid.uuid4().hex[:12]}"
        staging.mkdir(parents=True)
        try:
            for file, text in ((SCRIPT, script), (SIDECAR, json.dumps(meta, indent=2, sort_keys=True) + "\n")):
                with open(staging / file, "w", encoding="utf-8") as handle:
                    handle.write(text)
                    handle.flush()
                    os.fsync(handle.fileno())
            for file, origin in (files or {}).items():
                _copy_synced(Path(origin), staging / file)
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise _write_error(error, self.root) from None
        return staging

    def _check_writable(self, what: str) -> None:
        if self.read_only:
            raise BankError(
                f"cannot {what}: the shipped bank ({self.root}) is part of the installed package and read-only; "
                "use a bank folder of your own: `dv2s bank ... --bank DIR` (created on the first add or import), "
                "Bank(DIR) in Python, DV2S-v0 with bank_dir=DIR")

    def add(
        self,
        script: str,
        description: str,
        *,
        name: Optional[str] = None,
        elements: Optional[Mapping[str, Any]] = None,
        tags: Sequence[str] = (),
        map: Optional[str] = None,
        provenance: Optional[Mapping[str, Any]] = None,
        use_case: Optional[str] = None,
        upgrade_scenic2: bool = False,
        files: Optional[Mapping[str, PathLike]] = None,
    ) -> ScenarioEntry:
        """Add a scenario atomically; returns the new entry.

        Refuses (:class:`DuplicateScenarioError`, naming the existing entry) a
        script that is byte-for-byte or semantically identical to one in the
        bank, and (:class:`ScenarioRejectedError`) a script failing the safety check
        or its compile, sample and short run in the sandbox (:mod:`scenario_bank.sandbox`,
        with CPU, memory and wall-clock limits). ``provenance`` keys: kind (hand-written, generated, mined), video,
        parent, seed, generator, model, context_hash, date; mined entries also :data:`MINED_PROVENANCE_FIELDS`.

        ``upgrade_scenic2``: upgrade a script in Scenic 2 syntax to Scenic 3 first
        (:func:`scenario_bank.scenic2.upgrade_scenic2`, as ``dv2s bank add`` does), its rewrites and notes
        recorded in the provenance (``scenic2_rewrites``, ``scenic2_notes``). Without it a Scenic 2 script is
        refused with a :class:`ScenarioRejectedError` naming the construct, its line and this option.

        ``files``: entry file name (relative to the entry folder, e.g. ``"failure.webm"``) -> a file to copy
        there in the same atomic step, listed in the provenance's :data:`ENTRY_FILES`; provenance fields
        (:data:`ENTRY_FILE_KEYS`) name them by those relative names, so the entry stands alone.
        """
        self._check_writable("add a scenario")
        files = _check_files(files)
        script, provenance = _upgrade_scenic2(script, provenance, upgrade_scenic2)
        meta = self._make_meta(script, description, name, elements, tags, map, provenance, use_case)
        if files:
            meta["source"][ENTRY_FILES] = list(files)
        # before the lock: other writers do not wait for it
        _verify_or_name_scenic2(script, f"scenario {meta['name']!r}", upgrade_scenic2)
        with self._lock():
            self._load(locked=True)
            name = meta["name"] = self._free_name(meta["name"], explicit=name is not None)
            duplicate = self.find_duplicate(script, meta["elements"], meta["map"])
            if duplicate is not None:
                existing, how = duplicate
                raise DuplicateScenarioError(
                    f"not added: the script is {how} to bank entry {existing!r}; use that entry or change the script",
                    existing,
                )
            return self._add_locked(name, script, meta, files)

    def _add_locked(self, name: str, script: str, meta: Dict[str, Any],
                    files: Optional[Mapping[str, PathLike]] = None) -> ScenarioEntry:
        staging = self._stage_entry(name, script, meta, files)
        self._commit(staging, name)
        self._load(locked=True)
        return self._entries[name]

    def find_near_duplicate(self, script: str, elements: Mapping[str, Any],
                            map_name: Optional[str]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of an entry identical to this script (:meth:`find_duplicate`) or a near-duplicate
        of it (:func:`near_duplicate`: same map and elements, overlapping numeric parameter ranges)."""
        duplicate = self.find_duplicate(script, elements, map_name)
        if duplicate is not None:
            return duplicate
        wanted = normalize_elements(elements)
        for name in sorted(self._entries):
            entry = self._entries[name]
            if entry.map != map_name or entry.elements != wanted:
                continue
            try:
                other = entry.script
            except OSError:
                continue
            if near_duplicate(entry.elements, entry.map, other, wanted, map_name, script):
                return name, "a near-duplicate (same map and elements, overlapping parameter ranges)"
        return None

    def add_or_merge(
        self,
        script: str,
        description: str,
        *,
        name: Optional[str] = None,
        elements: Optional[Mapping[str, Any]] = None,
        tags: Sequence[str] = (),
        map: Optional[str] = None,
        provenance: Optional[Mapping[str, Any]] = None,
        use_case: Optional[str] = None,
        upgrade_scenic2: bool = False,
        files: Optional[Mapping[str, PathLike]] = None,
        near_copy_of: Optional[Callable[["ScenarioEntry"], bool]] = None,
    ) -> AddOutcome:
        """Add a scenario, or merge it into the entry it duplicates; one atomic step under the writers' lock.

        A script that is byte-for-byte or semantically identical to an entry, or a near-duplicate of
        one (:meth:`find_near_duplicate`), is not added: its provenance (with ``description`` and
        ``how``) is appended to that entry's ``source.merged`` list, the sidecar rewritten atomically.
        Otherwise the script is added as by :meth:`add`, except that ``name`` is a base name that
        gets a ``_2``, ``_3``... suffix when taken. Scripts are verified (safety check and sandbox)
        first either way (:class:`ScenarioRejectedError`). ``upgrade_scenic2`` and ``files`` are as for
        :meth:`add`; on a merge the files go to ``merged/<n>/<name>`` in the existing entry's folder (``n``:
        the merged record's 1-based position) and the merged record's provenance values naming them are
        rewritten to those paths, so every merged source keeps its own files.

        ``near_copy_of``: entries it returns True for (e.g. mined entries of the same family) are also merged
        into when their script's code differs from this one in at most :data:`NEAR_COPY_LINES` lines
        (:func:`changed_code_lines`), whatever their elements.
        """
        self._check_writable("add a scenario")
        files = _check_files(files)
        script, provenance = _upgrade_scenic2(script, provenance, upgrade_scenic2)
        meta = self._make_meta(script, description, name, elements, tags, map, provenance, use_case)
        _verify_or_name_scenic2(script, f"scenario {meta['name']!r}", upgrade_scenic2)
        with self._lock():
            self._load(locked=True)
            found = self.find_near_duplicate(script, meta["elements"], meta["map"])
            if found is None and near_copy_of is not None:
                found = self._find_near_copy(script, near_copy_of)
            if found is None:
                name = meta["name"] = self._free_name(meta["name"], explicit=False)
                if files:
                    meta["source"][ENTRY_FILES] = list(files)
                return AddOutcome("added", self._add_locked(name, script, meta, files))
            existing, how = found
            merged = {key: value for key, value in meta["source"].items() if value is not None and key != "merged"}
            merged.update(description=meta["description"], content_hash=meta["content_hash"], how=how)
            if files:
                prefix = f"merged/{len(self._entries[existing].source.get('merged') or []) + 1}/"
                folder = self._entries[existing].folder
                for file in files:
                    if not real_folder_in(self.root, f"{existing}/{prefix}{file}".rsplit("/", 1)[0]):
                        raise UnsafeBankInputError(
                            f"cannot merge into {existing!r}: a part of {existing}/{prefix}{file} is a symbolic link "
                            "or a file; bank entries hold real folders only: remove it and retry")
                try:
                    for file, origin in files.items():
                        with atomic_path(folder / (prefix + file)) as tmp:
                            _copy_synced(origin, tmp)
                except OSError as error:
                    raise _write_error(error, folder) from None
                merged = {key: prefix + value if key in ENTRY_FILE_KEYS and isinstance(value, str) and value in files
                          else value
                          for key, value in merged.items()}
                merged[ENTRY_FILES] = [prefix + file for file in files]
            self._append_merged(existing, merged)
            return AddOutcome("merged", self._entries[existing], how)

    def _find_near_copy(self, script: str, accept: Callable[["ScenarioEntry"], bool]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of the first entry ``accept`` takes whose code differs from ``script`` in at most
        :data:`NEAR_COPY_LINES` lines (caller holds the lock)."""
        for name in sorted(self._entries):
            entry = self._entries[name]
            if not accept(entry):
                continue
            try:
                other = entry.script
            except OSError:
                continue
            changed = changed_code_lines(other, script)
            if changed <= NEAR_COPY_LINES:
                return name, f"a near-copy ({changed} changed line(s) of code) of an entry of the same family"
        return None

    def update_source(self, name: str, fields: Mapping[str, Any]) -> "ScenarioEntry":
        """Set ``fields`` in entry ``name``'s provenance (``source``), rewriting its sidecar atomically under the
        writers' lock; returns the updated entry. ``kind``, ``merged`` and the entry's file list cannot be set."""
        self._check_writable("change a scenario's provenance")
        refused = sorted(set(fields) & {"kind", "merged", ENTRY_FILES})
        if refused:
            raise BankError(f"update_source cannot set {', '.join(refused)}; add or merge the scenario instead")
        with self._lock():
            self._load(locked=True)
            if name not in self._entries:
                raise UnknownScenarioError(f"no scenario named {name!r} in the bank at {self.root}")
            entry = self._entries[name]
            try:
                meta = _read_json(self.root, f"{name}/{SIDECAR}")
                meta.setdefault("source", {}).update(dict(fields))
                atomic_write_text(entry.folder / SIDECAR, json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
            except UnsafeInputError as error:
                raise _unsafe(error, "; the entry was not changed") from None
            except OSError as error:
                raise _write_error(error, entry.folder) from None
            self._load(locked=True)
            return self._entries[name]

    def _append_merged(self, name: str, record: Dict[str, Any]) -> None:
        """Append ``record`` to entry ``name``'s ``source.merged`` (caller holds the lock)."""
        entry = self._entries[name]
        path = entry.folder / SIDECAR
        try:
            meta = _read_json(self.root, f"{name}/{SIDECAR}")
            source = meta.setdefault("source", {})
            source["merged"] = list(source.get("merged") or []) + [record]
            atomic_write_text(path, json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
        except UnsafeInputError as error:
            raise _unsafe(error, "; the entry was not changed") from None
        except OSError as error:
            raise _write_error(error, entry.folder) from None
        self._load(locked=True)

    def _commit(self, staging: Path, name: str) -> None:
        try:
            os.rename(staging, self.root / name)
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            if error.errno in (errno.EEXIST, errno.ENOTEMPTY):
                raise BankError(f"an entry named {name!r} appeared while adding; retry with another name") from None
            raise _write_error(error, self.root) from None

    def _free_name(self, name: str, explicit: bool) -> str:
        if name not in self._entries and not (self.root / name).exists():
            return name
        if explicit:
            raise BankError(f"the bank already has an entry named {name!r}; choose another name or remove it first")
        k = 2
        while f"{name}_{k}" in self._entries or (self.root / f"{name}_{k}").exists():
            k += 1
        return f"{name}_{k}"

    def _make_meta(self, script, description, name, elements, tags, map_name, provenance, use_case) -> Dict[str, Any]:
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
        if not _NAME.match(name):
            raise BankError(f"invalid scenario name {name!r}: use lowercase letters, digits, '_' or '-'")
        try:
            elements = normalize_elements(elements or {})
        except ElementError as error:
            raise BankError(f"invalid elements: {error}") from None
        source = {key: None for key in _PROVENANCE_FIELDS}
        if (provenance or {}).get("kind") == "mined":
            source.update({key: None for key in MINED_PROVENANCE_FIELDS if key != "merged"})
        source.update(dict(provenance or {}))
        source["kind"] = source.get("kind") or "hand-written"
        if source["kind"] not in SOURCE_KINDS:
            raise BankError(f"provenance kind must be one of {SOURCE_KINDS}, got {source['kind']!r}")
        source["date"] = source.get("date") or _dt.date.today().isoformat()
        meta = {
            "schema_version": SIDECAR_VERSION,
            "name": name,
            "description": description.strip(),
            "elements": elements,
            "tags": sorted(set(tags)),
            "map": map_name,
            "use_case": use_case,
            "source": source,
            "content_hash": content_hash(script),
        }
        field_name = _control_character_field(meta)
        if field_name is not None:
            raise BankError(f"the scenario's {field_name} holds a control character: {_CONTROL_FIX}")
        return meta

    def copy_to(self, dest: PathLike) -> "Bank":
        """A writable copy of every entry in ``dest`` (a new or empty folder), made atomically.

        This is how a run starts a bank of its own from the read-only shipped bank.
        """
        dest = Path(dest)
        if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
            raise BankError(f"cannot copy the bank into {dest}: it exists and is not an empty folder; "
                            "pass a new folder, or use that bank as it is")
        staging = dest.parent / f".{dest.name}.copy-{uuid.uuid4().hex[:12]}"
        try:
            dest.parent.mkdir(parents=True, exist_ok=True)
            staging.mkdir()
            for entry in self:
                for relative, data in self._entry_bytes(entry):
                    target = staging / entry.name / relative
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(data)
            if os.path.lexists(self.root / LEGACY_INDEX):
                (staging / LEGACY_INDEX).write_bytes(read_regular_file(self.root / LEGACY_INDEX, MAX_SIDECAR_BYTES))
            if dest.exists():
                dest.rmdir()
            os.rename(staging, dest)
        except UnsafeInputError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise _unsafe(error, f"; nothing was written to {dest}") from None
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise _write_error(error, dest) from None
        return Bank(dest)

    def _entry_bytes(self, entry: ScenarioEntry) -> List[Tuple[str, bytes]]:
        """``(relative path, bytes)`` of an entry's script, sidecar and the files it lists that exist, each read
        as a capped regular file with no part a link (:func:`~scenario_bank.safe_files.read_in_folder`)."""
        out = [(SCRIPT, read_in_folder(self.root, f"{entry.name}/{SCRIPT}", MAX_SCRIPT_BYTES)),
               (SIDECAR, read_in_folder(self.root, f"{entry.name}/{SIDECAR}", MAX_SIDECAR_BYTES))]
        for file in entry_files(entry.source):
            if regular_file_in_folder(self.root, f"{entry.name}/{file}"):
                out.append((file, read_in_folder(self.root, f"{entry.name}/{file}", MAX_FILE_BYTES)))
        return out

    def remove(self, name: str) -> None:
        """Remove an entry atomically."""
        self._check_writable("remove a scenario")
        with self._lock():
            self._load(locked=True)
            if name not in self._entries and name not in self.problems:
                self.get(name)  # raises with near matches
            if not is_entry_name(name):
                raise BankError(f"cannot remove {name!r}: {self.problems.get(name, 'not a valid entry name')}; "
                                "remove or rename the folder by hand")
            trash = self.root / f".trash-{name}-{uuid.uuid4().hex[:12]}"
            os.rename(self.root / name, trash)
            if trash.is_symlink():
                trash.unlink()  # a linked entry: drop the link, never what it points to
            shutil.rmtree(trash, ignore_errors=True)
            self._load(locked=True)

    # ------------------------------------------------------- export/import
    def export(self, archive: PathLike, names: Optional[Iterable[str]] = None) -> Path:
        """Write entries (all by default) to one ``.tar.gz`` archive; returns its path."""
        archive = Path(archive)
        chosen = sorted(names) if names is not None else self.names()
        for n in chosen:
            self.get(n)
        try:
            with atomic_path(archive) as tmp:
                with tarfile.open(tmp, "w:gz") as tar:
                    header = json.dumps({"dv2s_bank_archive": BANK_VERSION, "entries": chosen}).encode()
                    _add_bytes(tar, ARCHIVE_HEADER, header)
                    for n in chosen:
                        for relative, data in self._entry_bytes(self._entries[n]):
                            _add_bytes(tar, f"{n}/{relative}", data)
        except UnsafeInputError as error:
            raise _unsafe(error, f"; {archive} was not written") from None
        except OSError as error:
            raise _write_error(error, archive.parent) from None
        return archive

    def import_archive(self, archive: PathLike, on_duplicate: str = "skip",
                       limits: Optional[ArchiveLimits] = None) -> Dict[str, List[str]]:
        """Import an archive written by :meth:`export`; all or nothing.

        Entries identical to existing ones are skipped (``on_duplicate="skip"``)
        or abort the import (``"error"``). Every new entry is verified like
        :meth:`add` (safety check, compile, sample and run in the sandbox); one
        failure (:class:`ScenarioRejectedError`) imports nothing. Returns ``{"added": [...], "skipped": [...]}``.

        The archive may come from anyone: its members are streamed into a private folder with the number of
        members, each file's size and the total capped while decompressing (``limits``, default
        :class:`~scenario_bank.safe_files.ArchiveLimits`), and only regular files and folders with safe names
        are accepted. A link, a device, an unsafe name (in a member, in the header or in a sidecar), a
        too large or too deeply nested file is one :class:`UnsafeBankInputError`, and nothing is imported.
        """
        if on_duplicate not in ("skip", "error"):
            raise ValueError("on_duplicate must be 'skip' or 'error'")
        self._check_writable("import scenarios")
        limits = limits or ArchiveLimits()
        staged: List[Tuple[str, Path]] = []
        added: List[str] = []
        skipped: List[str] = []
        with self._lock():
            self._load(locked=True)
            unpack = Path(tempfile.mkdtemp(dir=self.root, prefix=".import-"))
            try:
                try:
                    header, entries = _unpack_archive(Path(archive), unpack, limits)
                except UnsafeInputError as error:
                    raise _unsafe(error, "; nothing was imported") from None
                version = header.get("dv2s_bank_archive")
                if not isinstance(version, int):
                    raise BankError(f"{archive} is not a dv2s bank archive (no {ARCHIVE_HEADER} header)")
                if version > BANK_VERSION:
                    raise BankVersionError(f"{archive} was written by a newer dv2s-gym (format {version}); upgrade")
                journal = self.root / f".journal-{uuid.uuid4().hex[:12]}.json"
                try:
                    for n in entries:
                        folder = unpack / n
                        try:
                            meta = _validate_sidecar(_read_json(unpack, f"{n}/{SIDECAR}", limits.max_sidecar_bytes,
                                                                shown=f"its {SIDECAR}"), folder)
                            script = _read_text(unpack, f"{n}/{SCRIPT}", limits.max_script_bytes)
                        except (OSError, ValueError) as error:
                            message = error.strerror if isinstance(error, OSError) and error.strerror else error
                            raise UnsafeBankInputError(f"archive entry {n!r} is broken: {message}; nothing was "
                                                       "imported") from None
                        if meta.get("content_hash") != content_hash(script):
                            raise BankError(f"archive entry {n!r}: script does not match its content_hash; nothing was imported")
                        duplicate = self.find_duplicate(script, meta["elements"], meta["map"])
                        if duplicate is None:
                            duplicate = next(((a, "identical to another archive entry") for a, s in staged
                                              if content_hash(_read_text(s, SCRIPT, MAX_SCRIPT_BYTES))
                                              == meta["content_hash"]), None)
                        if duplicate is not None:
                            if on_duplicate == "error":
                                raise DuplicateScenarioError(
                                    f"archive entry {n!r} is {duplicate[1]} to {duplicate[0]!r}; nothing was imported",
                                    duplicate[0])
                            skipped.append(n)
                            continue
                        try:
                            verify(script, f"archive entry {n!r}")
                        except ScenarioRejectedError as error:
                            error.args = (f"{error}; nothing was imported",)
                            raise
                        target = self._free_name(n, explicit=False)
                        while target in [t for t, _ in staged]:
                            target = f"{target}_i"
                        meta["name"] = target
                        carried = {f: folder / f for f in entry_files(meta.get("source") or {})
                                   if regular_file_in_folder(unpack, f"{n}/{f}")}
                        staged.append((target, self._stage_entry(target, script, meta, carried)))
                    self._write_json_atomic(journal, {"adding": [t for t, _ in staged]})
                    for target, staging in staged:
                        self._commit(staging, target)
                        added.append(target)
                    journal.unlink()
                except BaseException:
                    for target in added:  # roll back what was renamed in
                        shutil.rmtree(self.root / target, ignore_errors=True)
                    for _, staging in staged:
                        shutil.rmtree(staging, ignore_errors=True)
                    if journal.exists():
                        journal.unlink()
                    raise
            finally:
                shutil.rmtree(unpack, ignore_errors=True)
            self._load(locked=True)
        return {"added": added, "skipped": skipped}

    def _clean_up(self) -> None:
        """Roll back imports a crash interrupted and drop leftovers of crashed writers.

        Runs under the writer lock only: then no other writer is mid-way.
        """
        if not self.root.is_dir():
            return
        for journal in self.root.glob(".journal-*.json"):
            try:
                names = _read_json(self.root, journal.name).get("adding", [])
            except (OSError, ValueError, AttributeError):
                names = []
            for n in names if isinstance(names, list) else []:
                if isinstance(n, str) and _NAME.match(n) and not (self.root / n).is_symlink():
                    shutil.rmtree(self.root / n, ignore_errors=True)
            journal.unlink(missing_ok=True)
        for pattern in (".staging-*", ".trash-*", ".import-*"):
            for stale in self.root.glob(pattern):
                shutil.rmtree(stale, ignore_errors=True)

    # ---------------------------------------------------------------- diff
    def diff(self, other: "Bank") -> BankDiff:
        """Entries only here, only there, changed (different content hash or metadata), same."""
        out = BankDiff()
        for n in sorted(set(self._entries) | set(other._entries)):
            if n not in other._entries:
                out.only_in_first.append(n)
            elif n not in self._entries:
                out.only_in_second.append(n)
            else:
                a, b = self._entries[n].meta, other._entries[n].meta
                strip = lambda m: {k: v for k, v in m.items() if k != "name"}  # noqa: E731
                (out.same if strip(a) == strip(b) else out.changed).append(n)
        return out


def _has_element(elements: Mapping[str, Any], wanted: str) -> bool:
    if ":" in wanted:
        who, what = wanted.split(":", 1)
        return [who, what] in elements.get("actions", [])
    return (
        wanted == elements.get("road")
        or wanted in elements.get("participants", [])
        or any(a[1] == wanted for a in elements.get("actions", []))
        or any(r[1] == wanted for r in elements.get("relations", []))
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
    """Raise :class:`NotABankError` unless ``root`` is empty or holds a bank entry (or the legacy index)."""
    if not visible or any(d.name == LEGACY_INDEX for d in visible):
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


def _copy_synced(origin: Path, dest: Path) -> None:
    """Copy ``origin`` to ``dest`` (parents made) and flush it to disk."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(origin, dest)
    with open(dest, "rb") as handle:
        os.fsync(handle.fileno())


def _check_files(files: Optional[Mapping[str, PathLike]]) -> Dict[str, Path]:
    """``files`` (entry file name -> file to copy) checked: valid names, existing regular files."""
    out: Dict[str, Path] = {}
    for name, origin in (files or {}).items():
        entry_file_name(name)
        if not Path(origin).is_file():
            raise BankError(f"the entry file {name!r} to add ({origin}) does not exist or is not a file; "
                            "pass an existing file")
        out[name] = Path(origin)
    return out


def _write_error(error: OSError, where: Path) -> BankError:
    if error.errno == errno.ENOSPC:
        return BankError(f"the disk is full while writing to {where}; free some space and retry (the bank is unchanged)")
    return BankError(f"could not write to {where}: {error.strerror or error}; the bank is unchanged")


def _add_bytes(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = 0
    tar.addfile(info, io.BytesIO(data))


def _member_cap(limits: ArchiveLimits) -> Callable[[str], int]:
    """The size cap of an archive member, by its role: header, sidecar, script or another file."""
    def cap(name: str) -> int:
        if name == ARCHIVE_HEADER or name.endswith("/" + SIDECAR) and name.count("/") == 1:
            return limits.max_sidecar_bytes
        if name.endswith("/" + SCRIPT) and name.count("/") == 1:
            return limits.max_script_bytes
        return limits.max_file_bytes
    return cap


def _unpack_archive(archive: Path, dest: Path, limits: ArchiveLimits) -> Tuple[Dict[str, Any], List[str]]:
    """Stream a bank archive's members into ``dest`` (:func:`~scenario_bank.safe_files.extract_archive`); return
    its header and its entry names, checked: safe names, no repeats, every member belonging to one of them."""
    try:
        sizes = extract_archive(archive, dest, _member_cap(limits), limits)
    except FileNotFoundError:
        raise FileNotFoundError(errno.ENOENT, f"archive {str(archive)!r} does not exist", str(archive)) from None
    except (tarfile.TarError, EOFError, OSError, zlib.error, lzma.LZMAError) as error:
        if isinstance(error, OSError) and error.errno == errno.ENOSPC:
            raise _write_error(error, dest) from None
        raise BankError(f"{archive} is not a readable bank archive: {error}") from None
    if ARCHIVE_HEADER not in sizes:
        return {}, []
    header = load_json_bounded(read_in_folder(dest, ARCHIVE_HEADER, limits.max_sidecar_bytes), MAX_JSON_DEPTH,
                               f"{archive}: {ARCHIVE_HEADER}")
    if not isinstance(header, dict):
        raise UnsafeInputError(f"{archive}: {ARCHIVE_HEADER} is not a JSON object; it is not a bank archive")
    entries = header.get("entries", [])
    if not isinstance(entries, list) or len(entries) > limits.max_members:
        raise UnsafeInputError(f"{archive}: {ARCHIVE_HEADER} 'entries' must be a list of at most "
                               f"{limits.max_members} entry names")
    for n in entries:
        validate_entry_name(n, f"entry name in {archive}'s {ARCHIVE_HEADER}")
    if len(set(entries)) != len(entries):
        raise UnsafeInputError(f"{archive}: {ARCHIVE_HEADER} lists an entry twice; it is not a bank archive")
    stray = sorted(m for m in sizes if m != ARCHIVE_HEADER and m.split("/", 1)[0] not in entries)
    if stray:
        raise UnsafeInputError(f"{archive} holds {stray[0]!r}, which belongs to no entry its {ARCHIVE_HEADER} "
                               "lists; it is not a bank archive written by `dv2s bank export`")
    return header, entries
