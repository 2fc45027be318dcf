"""A bank's archives: :func:`export_archive` writes entries to one ``.tar.gz``; :func:`import_archive` adds an
archive's entries to a bank, all or nothing (``Bank.export`` and ``Bank.import_archive`` call them).

An archive may come from anyone: it is streamed into a private folder under caps before anything of it is used
(:func:`~scenario_bank.safe_files.extract_archive`), and every name in it is checked against one safe pattern.
"""

from __future__ import annotations

import errno
import io
import json
import lzma
import shutil
import tarfile
import tempfile
import zlib
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from scenario_bank.admission import check_on_duplicate, verify
from scenario_bank.atomic import atomic_path
from scenario_bank.dedup import content_hash
from scenario_bank.entries import (BANK_VERSION, MAX_JSON_DEPTH, SCRIPT, SIDECAR, PathLike,
                                   entry_bytes, entry_files, read_json, read_text, unsafe_input, validate_sidecar)
from scenario_bank.records import Sidecar
from scenario_bank.errors import (BankError, BankVersionError, DuplicateScenarioError, MissingFileError, ScenarioRejectedError,
                                  UnsafeBankInputError, bank_write_error)
from scenario_bank.safe_files import (ArchiveLimits, UnsafeInputError, extract_archive, load_json_bounded,
                                      read_in_folder, regular_file_in_folder, validate_entry_name)

__all__ = ["ARCHIVE_HEADER", "export_archive", "import_archive"]

ARCHIVE_HEADER = "bank-archive.json"
"""The archive's first member: its format version and its entry names."""


def export_archive(bank: Any, archive: PathLike, names: Optional[Iterable[str]] = None) -> Path:
    """Write entries of ``bank`` (a :class:`~scenario_bank.bank.Bank`; all by default) to one ``.tar.gz`` archive; returns its path."""
    archive = Path(archive)
    chosen = sorted(names) if names is not None else bank.names()
    for n in chosen:
        bank.get(n)
    try:
        with atomic_path(archive) as tmp:
            with tarfile.open(tmp, "w:gz") as tar:
                header = json.dumps({"dv2s_bank_archive": BANK_VERSION, "entries": chosen}).encode()
                _add_bytes(tar, ARCHIVE_HEADER, header)
                for n in chosen:
                    for relative, data in entry_bytes(bank.root, bank.get(n)):
                        _add_bytes(tar, f"{n}/{relative}", data)
    except UnsafeInputError as error:
        raise unsafe_input(error, f"; {archive} was not written") from None
    except OSError as error:
        raise bank_write_error(error, archive.parent) from None
    return archive


def _check_header(header: Dict[str, Any], archive: PathLike) -> None:
    """Refuse an archive without the bank archive header, or of a newer format than this dv2s-gym reads."""
    version = header.get("dv2s_bank_archive")
    if not isinstance(version, int):
        raise BankError(f"{archive} is not a dv2s bank archive (no {ARCHIVE_HEADER} header)")
    if version > BANK_VERSION:
        raise BankVersionError(f"{archive} was written by a newer dv2s-gym (format {version}); upgrade")


def _read_entry(unpack: Path, n: str, limits: ArchiveLimits) -> Tuple[Sidecar, str]:
    """``(sidecar, script)`` of the unpacked archive entry ``n``, checked (readable, valid, the script the
    sidecar's content hash names)."""
    try:
        meta = validate_sidecar(read_json(unpack, f"{n}/{SIDECAR}", limits.max_sidecar_bytes,
                                          shown=f"its {SIDECAR}"), unpack / n)
        script = read_text(unpack, f"{n}/{SCRIPT}", limits.max_script_bytes)
    except (OSError, ValueError) as error:
        message = error.strerror if isinstance(error, OSError) and error.strerror else error
        raise UnsafeBankInputError(f"archive entry {n!r} is broken: {message}; nothing was imported") from None
    if meta.content_hash != content_hash(script):
        raise BankError(f"archive entry {n!r}: script does not match its content_hash; nothing was imported")
    return meta, script


def import_archive(bank: Any, archive: PathLike, on_duplicate: str = "skip",
                   limits: Optional[ArchiveLimits] = None) -> Dict[str, List[str]]:
    """Import into ``bank`` (a :class:`~scenario_bank.bank.Bank`) an archive written by :func:`export_archive`; all or
    nothing, through :meth:`Bank.add_together <scenario_bank.bank.Bank.add_together>`.

    ``on_duplicate`` (of :data:`~scenario_bank.admission.ON_DUPLICATE`, the values an import takes): entries
    identical to existing ones (or to another entry of the archive) are skipped (``"skip"``) or abort the import
    (``"error"``). Every new entry is verified like :meth:`Bank.add <scenario_bank.bank.Bank.add>` (safety check,
    compile, sample and run in the sandbox); one failure (:class:`ScenarioRejectedError`) imports nothing. Returns
    ``{"added": [...], "skipped": [...]}``.

    The archive may come from anyone: its members are streamed into a private folder with the number of
    members, each file's size and the total capped while decompressing (``limits``, default
    :class:`~scenario_bank.safe_files.ArchiveLimits`), and only regular files and folders with safe names
    are accepted. A link, a device, an unsafe name (in a member, in the header or in a sidecar), a
    too large or too deeply nested file is one :class:`UnsafeBankInputError`, and nothing is imported.
    """
    check_on_duplicate(on_duplicate, "import")
    limits = limits or ArchiveLimits()
    skipped: List[str] = []
    with bank.add_together("import scenarios", duplicate_label="archive entry") as batch:
        unpack = Path(tempfile.mkdtemp(dir=bank.root, prefix=".import-"))
        try:
            try:
                header, entries = _unpack_archive(Path(archive), unpack, limits)
            except UnsafeInputError as error:
                raise unsafe_input(error, "; nothing was imported") from None
            _check_header(header, archive)
            for n in entries:
                meta, script = _read_entry(unpack, n, limits)
                duplicate = batch.duplicate_of(script, meta.elements, meta.map)
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
                carried = {f: unpack / n / f for f in entry_files(meta.provenance)
                           if regular_file_in_folder(unpack, f"{n}/{f}")}
                batch.stage(script, meta, carried)
        finally:
            shutil.rmtree(unpack, ignore_errors=True)
    return {"added": batch.names, "skipped": skipped}


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
        raise MissingFileError(f"archive {str(archive)!r} does not exist; check the path (`dv2s bank export` writes "
                               "an archive)") from None
    except (tarfile.TarError, EOFError, OSError, zlib.error, lzma.LZMAError) as error:
        if isinstance(error, OSError) and error.errno == errno.ENOSPC:
            raise bank_write_error(error, dest) from None
        raise BankError(f"{archive} is not a readable bank archive: {error}; pass an archive made by "
                       "`dv2s bank export`") from None
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
