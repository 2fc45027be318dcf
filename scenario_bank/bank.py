"""The scenario bank: a versioned, validated, searchable folder of Scenic scenarios (:class:`Bank`).

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

:class:`Bank` is the one interface; it is built of :mod:`scenario_bank.entries` (the entry folder, its sidecar
and provenance, listing a folder), :mod:`scenario_bank.dedup` (when two scenarios are the same),
:mod:`scenario_bank.admission` (the checks a script passes to enter), :mod:`scenario_bank.archives` (export and
import) and :mod:`scenario_bank.errors`. The names callers use (the errors, the size limits, the provenance
fields, the duplicate checks: ``__all__``) are importable from here too. It imports nothing outside
``scenario_bank``.
"""

from __future__ import annotations

import difflib
import errno
import fcntl
import json
import os
import random
import shutil
import uuid
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import (Any, Callable, Dict, Iterable, Iterator, List, Literal, Mapping, Optional, Sequence, Tuple, Union,
                    overload)

from scenario_bank.admission import ON_DUPLICATE, check_on_duplicate, upgrade_if_asked, verify, verify_or_name_scenic2
from scenario_bank.archives import export_archive, import_archive
from scenario_bank.atomic import atomic_path, atomic_write_json, atomic_write_text
from scenario_bank.cache import keyed_cache_dir
from scenario_bank.dedup import (NEAR_COPY_LINES, changed_code_lines, content_hash, find_duplicate, find_near_copy,
                                 find_near_duplicate, near_duplicate, param_ranges, semantic_key)
from scenario_bank.families import near_duplicates_of
from scenario_bank.entries import (BANK_VERSION, ENTRY_FILE_KEYS, ENTRY_FILES, MAX_FILE_BYTES,
                                   MAX_JSON_DEPTH, MAX_SCRIPT_BYTES, MAX_SIDECAR_BYTES, MINED_PROVENANCE_FIELDS, NEW_ENTRY_NAME, SCRIPT, SIDECAR, SIDECAR_VERSION,
                                   SOURCE_KINDS, PathLike, ScenarioEntry, entry_bytes,
                                   entry_file_name, entry_files, entry_matches, new_sidecar, read_json, scan_entries,
                                   unsafe_input)
from scenario_bank.elements import Elements
from scenario_bank.records import CONTROL_FIX, Provenance, Sidecar, control_character_field
from scenario_bank.errors import (BankError, BankOptionError, BankVersionError, DuplicateScenarioError, NotABankError,
                                  NearDuplicateWarning,
                                  ScenarioRejectedError, UnknownScenarioError, UnsafeBankInputError, WrongTypeError,
                                  bank_write_error)
from scenario_bank.safe_files import (ArchiveLimits, UnsafeInputError, is_entry_name, load_json_bounded,
                                      read_regular_file, real_folder_in, validate_entry_name)

BANK_DIR = Path(__file__).resolve().parent / "scenarios"
"""Folder of the bank shipped with dv2s-gym."""

__all__ = [
    "BANK_DIR",
    "BANK_VERSION",
    "SIDECAR_VERSION",
    "Bank",
    "ScenarioEntry",
    "Provenance",
    "Sidecar",
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
    "EntryBatch",
    "param_ranges",
    "near_duplicate",
    "changed_code_lines",
    "NEAR_COPY_LINES",
    "ENTRY_FILE_KEYS",
    "ENTRY_FILES",
    "entry_files",
    "entry_file_name",
    "ON_DUPLICATE",
    "verify", "MAX_JSON_DEPTH"]

INDEX = "index.json"
WRITERS_LOCK = ".dv2s-writers.lock"
"""The file writers of a bank lock (``flock``), in the bank folder itself."""
_MAX_INDEX_BYTES = 256 << 20


@dataclass
class AddOutcome:
    """What :meth:`Bank.add` with ``on_duplicate="merge"`` did: ``status`` "added" (a new ``entry``) or "merged"
    (the provenance was appended to the existing ``entry``'s ``source.merged``; ``how`` says why)."""

    status: str
    entry: ScenarioEntry
    how: Optional[str] = None


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
        listing = scan_entries(self.root, cached)
        self._entries, self.problems, self._semantic_keys = listing.entries, listing.problems, listing.semantic_keys
        fresh = listing.index
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
        return [self._entries[name] for name in sorted(self._entries)
                if entry_matches(self._entries[name], tag, needle, wanted, map, source)]

    def tags(self) -> List[str]:
        """Every tag in the bank."""
        return sorted({t for e in self._entries.values() for t in e.sidecar.tags})

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
            "by_source": count(e.source.kind or "?" for e in entries),
            "by_road": count(e.elements.road or "?" for e in entries),
            "by_tag": count(t for e in entries for t in e.tags),
            "by_participant": count(p for e in entries for p in set(e.elements.participants)),
        }

    def find_duplicate(self, script: str, elements: Optional[Elements],
                       map_name: Optional[str]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of an entry byte-for-byte identical to this script, or semantically identical (same
        elements, map and parameter ranges; when ``elements`` is given), or ``None``."""
        return find_duplicate(self._entries, self._semantic_keys, script, elements, map_name)

    # ------------------------------------------------------------- writing
    @contextmanager
    def _lock(self) -> Iterator[None]:
        created = not self.root.exists()
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            handle = open(self.root / WRITERS_LOCK, "a+")
        except OSError as error:
            raise bank_write_error(error, self.root) from None
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

    def _stage_entry(self, name: str, script: str, meta: Union[Sidecar, Dict[str, Any]],
                     files: Optional[Mapping[str, PathLike]] = None) -> Path:
        """Write an entry (its script, its sidecar ``meta``: written as JSON here, and the ``files`` it carries) into
        a hidden staging folder of the bank; the folder."""
        meta = meta.to_dict() if isinstance(meta, Sidecar) else meta
        field_name = control_character_field(meta)
        if field_name is not None:  # every write passes here, whatever built the sidecar
            raise BankError(f"the sidecar field {field_name!r} of {name} holds a control character: {CONTROL_FIX}")
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
            raise bank_write_error(error, self.root) from None
        return staging

    def _check_writable(self, what: str) -> None:
        if self.read_only:
            raise BankError(
                f"cannot {what}: the shipped bank ({self.root}) is part of the installed package and read-only; "
                "use a bank folder of your own: `dv2s bank ... --bank DIR` (created on the first add or import), "
                "Bank(DIR) in Python, DV2S-v0 with bank_dir=DIR")

    @overload
    def add(self, script: str, entry: Union[str, Sidecar], *, upgrade_scenic2: bool = ...,
            files: Optional[Mapping[str, PathLike]] = ..., on_duplicate: Literal["error"] = ...,
            near_copy_of: None = ...) -> ScenarioEntry: ...

    @overload
    def add(self, script: str, entry: Union[str, Sidecar], *, upgrade_scenic2: bool = ...,
            files: Optional[Mapping[str, PathLike]] = ..., on_duplicate: Literal["merge"],
            near_copy_of: Optional[Callable[[ScenarioEntry], bool]] = ...) -> AddOutcome: ...

    def add(
        self,
        script: str,
        entry: Union[str, Sidecar],
        *,
        upgrade_scenic2: bool = False,
        files: Optional[Mapping[str, PathLike]] = None,
        on_duplicate: str = "error",
        near_copy_of: Optional[Callable[[ScenarioEntry], bool]] = None,
    ) -> Union[ScenarioEntry, AddOutcome]:
        """Add a scenario atomically, in one step under the writers' lock.

        ``entry``: the new entry's fields, a :class:`~scenario_bank.records.Sidecar` (its ``description``,
        ``name``, ``elements``, ``tags``, ``map``, ``use_case`` and provenance ``source``), or its description
        alone (a string). ``map`` is read from the script's ``param map`` when not given, ``name`` made from the
        description. The provenance ``source`` (a :class:`~scenario_bank.records.Provenance`) fields: kind
        (hand-written, generated, mined), video, parent, seed, generator, model, context_hash, date; mined
        entries also :data:`MINED_PROVENANCE_FIELDS`.

        Every script is verified first: a script failing the safety check or its compile, sample and short run in
        the sandbox (:mod:`scenario_bank.sandbox`, with CPU, memory and wall-clock limits) is refused
        (:class:`ScenarioRejectedError`).

        ``on_duplicate`` says what happens to a script the bank already holds:

        - ``"error"`` (the default): a script byte-for-byte or semantically identical (same elements, map and
          parameter ranges) to an entry is refused (:class:`DuplicateScenarioError`, naming that entry);
          ``name`` is the new entry's name, and a name already taken is refused (:class:`BankError`). Returns
          the new :class:`ScenarioEntry`. A new entry that is a near-duplicate of others (same map and elements,
          overlapping parameter ranges: one scenario family for mining and the loop) is added with a
          :class:`~scenario_bank.errors.NearDuplicateWarning` naming them.
        - ``"merge"`` (what failure mining uses): a script identical to an entry or a near-duplicate of one
          (:meth:`find_near_duplicate`: same map and elements, overlapping numeric parameter ranges) is not
          added: its provenance (with ``description`` and ``how``) is appended to that entry's
          ``source.merged`` list, the sidecar rewritten atomically. ``name`` is a base name that gets a ``_2``,
          ``_3``... suffix when taken. ``near_copy_of``: entries it returns True for (e.g. mined entries of
          the same family) are also merged into when their script's code differs from this one in at most
          :data:`NEAR_COPY_LINES` lines (:func:`changed_code_lines`), whatever their elements. Returns an
          :class:`AddOutcome` (``status`` "added" or "merged").

        ``upgrade_scenic2``: upgrade a script in Scenic 2 syntax to Scenic 3 first
        (:func:`scenario_bank.scenic2.upgrade_scenic2`, as ``dv2s bank add`` does), its rewrites and notes
        recorded in the provenance (``scenic2_rewrites``, ``scenic2_notes``). Without it a Scenic 2 script is
        refused with a :class:`ScenarioRejectedError` naming the construct, its line and this option.

        ``files``: entry file name (relative to the entry folder, e.g. ``"failure.webm"``) -> a file to copy
        there in the same atomic step, listed in the provenance's :data:`ENTRY_FILES`; provenance fields
        (:data:`ENTRY_FILE_KEYS`) name them by those relative names, so the entry stands alone. On a merge the
        files go to ``merged/<n>/<name>`` in the existing entry's folder (``n``: the merged record's 1-based
        position) and the merged record's provenance values naming them are rewritten to those paths, so every
        merged source keeps its own files.
        """
        given = _new_entry(entry)
        _check_add_options(on_duplicate, near_copy_of)
        self._check_writable("add a scenario")
        files = _check_files(files)
        script, provenance = upgrade_if_asked(script, given.source, upgrade_scenic2)
        meta = new_sidecar(script, given.description, given.name, given.elements, given.tags,
                           given.map or None, provenance, given.use_case)
        # before the lock: other writers do not wait for it
        verify_or_name_scenic2(script, f"scenario {meta.name!r}", upgrade_scenic2)
        with self._lock():
            self._load(locked=True)
            if on_duplicate == "merge":
                return self._add_or_merge_locked(script, meta, files, near_copy_of)
            added = self._add_new_locked(script, meta, files, explicit_name=given.name is not None)
        twins = near_duplicates_of(self, added.name)
        if twins:
            warnings.warn(NearDuplicateWarning(added.name, twins), stacklevel=2)
        return added

    def _add_new_locked(self, script: str, meta: Sidecar, files: Dict[str, Path], *,
                        explicit_name: bool) -> ScenarioEntry:
        """:meth:`add` with ``on_duplicate="error"`` once verified, under the lock: refuse a name taken (when
        given) or a duplicate script, else write the entry."""
        meta = meta.replace(name=self._free_name(meta.name, explicit=explicit_name))
        duplicate = self.find_duplicate(script, meta.elements, meta.map)
        if duplicate is not None:
            existing, how = duplicate
            raise DuplicateScenarioError(
                f"not added: the script is {how} to bank entry {existing!r}; use that entry or change the script",
                existing,
            )
        return self._add_locked(meta.name, script, _listing_files(meta, files), files)

    def _add_or_merge_locked(self, script: str, meta: Sidecar, files: Dict[str, Path],
                             near_copy_of: Optional[Callable[[ScenarioEntry], bool]]) -> AddOutcome:
        """:meth:`add` with ``on_duplicate="merge"`` once verified, under the lock."""
        found = self.find_near_duplicate(script, meta.elements, meta.map)
        if found is None and near_copy_of is not None:
            found = find_near_copy(self._entries, script, near_copy_of)
        if found is None:
            meta = meta.replace(name=self._free_name(meta.name, explicit=False))
            return AddOutcome("added", self._add_locked(meta.name, script, _listing_files(meta, files), files))
        existing, how = found
        merged = {key: value for key, value in meta.source.to_dict().items() if value is not None and key != "merged"}
        merged.update(description=meta.description, content_hash=meta.content_hash, how=how)
        if files:
            prefix = f"merged/{len(self._entries[existing].source.merged or ()) + 1}/"
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
                raise bank_write_error(error, folder) from None
            merged = {key: prefix + value if key in ENTRY_FILE_KEYS and isinstance(value, str) and value in files
                      else value
                      for key, value in merged.items()}
            merged[ENTRY_FILES] = [prefix + file for file in files]
        self._append_merged(existing, merged)
        return AddOutcome("merged", self._entries[existing], how)

    def _add_locked(self, name: str, script: str, meta: Sidecar,
                    files: Optional[Mapping[str, PathLike]] = None) -> ScenarioEntry:
        staging = self._stage_entry(name, script, meta, files)
        self._commit(staging, name)
        self._load(locked=True)
        return self._entries[name]

    def find_near_duplicate(self, script: str, elements: Elements,
                            map_name: Optional[str]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of an entry identical to this script (:meth:`find_duplicate`) or a near-duplicate
        of it (:func:`near_duplicate`: same map and elements, overlapping numeric parameter ranges)."""
        return find_near_duplicate(self._entries, self._semantic_keys, script, elements, map_name)

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
                meta = read_json(self.root, f"{name}/{SIDECAR}")
                meta.setdefault("source", {}).update(dict(fields))
                atomic_write_text(entry.folder / SIDECAR, json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
            except UnsafeInputError as error:
                raise unsafe_input(error, "; the entry was not changed") from None
            except OSError as error:
                raise bank_write_error(error, entry.folder) from None
            self._load(locked=True)
            return self._entries[name]

    def _append_merged(self, name: str, record: Dict[str, Any]) -> None:
        """Append ``record`` to entry ``name``'s ``source.merged`` (caller holds the lock)."""
        entry = self._entries[name]
        path = entry.folder / SIDECAR
        try:
            meta = read_json(self.root, f"{name}/{SIDECAR}")
            source = meta.setdefault("source", {})
            source["merged"] = list(source.get("merged") or []) + [record]
            atomic_write_text(path, json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
        except UnsafeInputError as error:
            raise unsafe_input(error, "; the entry was not changed") from None
        except OSError as error:
            raise bank_write_error(error, entry.folder) from None
        self._load(locked=True)

    def _commit(self, staging: Path, name: str) -> None:
        try:
            os.rename(staging, self.root / name)
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            if error.errno in (errno.EEXIST, errno.ENOTEMPTY):
                raise BankError(f"an entry named {name!r} appeared while adding; retry with another name") from None
            raise bank_write_error(error, self.root) from None

    def _free_name(self, name: str, explicit: bool) -> str:
        if name not in self._entries and not (self.root / name).exists():
            return name
        if explicit:
            raise BankError(f"the bank already has an entry named {name!r}; choose another name or remove it first")
        k = 2
        while f"{name}_{k}" in self._entries or (self.root / f"{name}_{k}").exists():
            k += 1
        return f"{name}_{k}"

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
                for relative, data in entry_bytes(self.root, entry):
                    target = staging / entry.name / relative
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(data)
            if dest.exists():
                dest.rmdir()
            os.rename(staging, dest)
        except UnsafeInputError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise unsafe_input(error, f"; nothing was written to {dest}") from None
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise bank_write_error(error, dest) from None
        return Bank(dest)

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

    @contextmanager
    def add_together(self, what: str, duplicate_label: str = "entry added with it") -> Iterator["EntryBatch"]:
        """Add several entries in one all-or-nothing step, under the writers' lock: the body stages entries on the
        :class:`EntryBatch` it is given; when it returns they are all renamed into the bank (a journal lets a crash
        be rolled back by the next writer), when it raises none is. ``what`` names the operation in the error of
        a read-only bank; ``duplicate_label`` names a staged entry in :meth:`EntryBatch.duplicate_of`.
        :meth:`import_archive` adds an archive's entries this way."""
        self._check_writable(what)
        with self._lock():
            self._load(locked=True)
            batch = EntryBatch(self, duplicate_label)
            try:
                yield batch
                batch._commit_all()
            except BaseException:
                batch._roll_back()
                raise
            self._load(locked=True)

    # ------------------------------------------------------- export/import
    def export(self, archive: PathLike, names: Optional[Iterable[str]] = None) -> Path:
        """Write entries (all by default) to one ``.tar.gz`` archive; returns its path
        (:func:`~scenario_bank.archives.export_archive`)."""
        return export_archive(self, archive, names)

    def import_archive(self, archive: PathLike, on_duplicate: str = "skip",
                       limits: Optional[ArchiveLimits] = None) -> Dict[str, List[str]]:
        """Import an archive written by :meth:`export`; all or nothing
        (:func:`~scenario_bank.archives.import_archive`, which says what is checked).

        Entries identical to existing ones are skipped (``on_duplicate="skip"``) or abort the import
        (``"error"``). Every new entry is verified like :meth:`add`. Returns ``{"added": [...], "skipped": [...]}``.
        """
        return import_archive(self, archive, on_duplicate, limits)

    def _clean_up(self) -> None:
        """Roll back imports a crash interrupted and drop leftovers of crashed writers.

        Runs under the writer lock only: then no other writer is mid-way.
        """
        if not self.root.is_dir():
            return
        for journal in self.root.glob(".journal-*.json"):
            try:
                names = read_json(self.root, journal.name).get("adding", [])
            except (OSError, ValueError, AttributeError):
                names = []
            for n in names if isinstance(names, list) else []:
                if isinstance(n, str) and NEW_ENTRY_NAME.match(n) and not (self.root / n).is_symlink():
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
                a, b = self._entries[n].sidecar.to_dict(), other._entries[n].sidecar.to_dict()
                strip = lambda m: {k: v for k, v in m.items() if k != "name"}  # noqa: E731
                (out.same if strip(a) == strip(b) else out.changed).append(n)
        return out


class EntryBatch:
    """The entries staged by one :meth:`Bank.add_together`: checked against the bank and each other, written into
    hidden staging folders, renamed into the bank together when the block ends."""

    def __init__(self, bank: Bank, duplicate_label: str) -> None:
        self.bank = bank
        self._label = duplicate_label
        self._staged: List[Tuple[str, Path, str]] = []  # (name, staging folder, content hash)
        self._added: List[str] = []
        self._journal = bank.root / f".journal-{uuid.uuid4().hex[:12]}.json"

    @property
    def names(self) -> List[str]:
        """The names the staged entries get, in staging order."""
        return [name for name, _, _ in self._staged]

    def duplicate_of(self, script: str, elements: Optional[Elements],
                     map_name: Optional[str]) -> Optional[Tuple[str, str]]:
        """``(name, how)`` of a bank entry this script duplicates (:meth:`Bank.find_duplicate`) or of an entry staged
        before with the same script, or ``None``."""
        found = self.bank.find_duplicate(script, elements, map_name)
        if found is None:
            digest = content_hash(script)
            found = next(((name, f"identical to another {self._label}") for name, _, staged in self._staged
                          if staged == digest), None)
        return found

    def stage(self, script: str, meta: Sidecar, files: Optional[Mapping[str, PathLike]] = None) -> str:
        """Stage a verified entry (its sidecar ``meta``, the ``files`` it carries, already listed in its
        provenance) under its name, or the next free one (``_2``, ...; ``_i`` appended while another staged entry
        has it); returns the name. The entry enters the bank when the :meth:`Bank.add_together` block ends."""
        meta = meta.to_dict()
        name = self.bank._free_name(meta["name"], explicit=False)
        while name in self.names:
            name = f"{name}_i"
        meta["name"] = name
        self._staged.append((name, self.bank._stage_entry(name, script, meta, files), content_hash(script)))
        return name

    def _commit_all(self) -> None:
        self.bank._write_json_atomic(self._journal, {"adding": self.names})
        for name, staging, _ in self._staged:
            self.bank._commit(staging, name)
            self._added.append(name)
        self._journal.unlink()

    def _roll_back(self) -> None:
        for name in self._added:  # roll back what was renamed in
            shutil.rmtree(self.bank.root / name, ignore_errors=True)
        for _, staging, _ in self._staged:
            shutil.rmtree(staging, ignore_errors=True)
        if self._journal.exists():
            self._journal.unlink()


def _copy_synced(origin: Path, dest: Path) -> None:
    """Copy ``origin`` to ``dest`` (parents made) and flush it to disk."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(origin, dest)
    with open(dest, "rb") as handle:
        os.fsync(handle.fileno())


def _new_entry(entry: Union[str, Sidecar]) -> Sidecar:
    """The new entry's fields for :meth:`Bank.add`: a :class:`Sidecar` as given, or one holding only the
    description given as a string. A sidecar holding what a new entry cannot take (a ``story``, other keys) is a
    :class:`TypeError`, as is anything else than a string or a sidecar."""
    if isinstance(entry, str):
        return Sidecar(description=entry)
    if not isinstance(entry, Sidecar):
        raise WrongTypeError(f"Bank.add() takes the new entry as a Sidecar or its description as a string, not "
                        f"{type(entry).__name__}")
    if entry.story is not None or entry.extra:
        raise WrongTypeError("Bank.add() writes a new entry's sidecar from its description, name, elements, tags, map, "
                        "use_case and source; a story or other keys would be lost: leave them out")
    return entry


def _listing_files(meta: Sidecar, files: Mapping[str, Path]) -> Sidecar:
    """A new entry's sidecar with the ``files`` it carries listed in its provenance (:data:`ENTRY_FILES`)."""
    return meta.replace(source=meta.source.replace(files=tuple(files))) if files else meta


def _check_add_options(on_duplicate: str, near_copy_of: Optional[Callable[[ScenarioEntry], bool]]) -> None:
    """Refuse an ``on_duplicate`` that :meth:`Bank.add` does not know, and ``near_copy_of`` without a merge."""
    check_on_duplicate(on_duplicate, "add")
    if near_copy_of is not None and on_duplicate != "merge":
        raise BankOptionError("near_copy_of only applies to on_duplicate='merge' (near-copies are merged into, "
                         "never refused); pass on_duplicate='merge' or drop near_copy_of")


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
