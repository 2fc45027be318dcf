"""Bounded, non-following reads of bank folders and bank archives, which may come from anyone.

Every reader of a bank folder or archive goes through these helpers:

- :func:`validate_entry_name` / :func:`validate_relative_path`: one safe pattern for every name read from a
  folder listing, an archive header, a sidecar or the command line (no ``/``, no ``..``, no NUL, not absolute).
- :func:`read_regular_file` / :func:`read_in_folder`: open without following symbolic links and without
  blocking (a FIFO never hangs the reader), refuse anything but a regular file (checked on the open file
  descriptor, so a swap after a check changes nothing), and read at most the cap plus one byte.
- :func:`load_json_bounded`: a non-recursive pre-scan of the nesting depth before :func:`json.loads`, so a
  deeply nested document is one clear error instead of a ``RecursionError``.
- :func:`extract_archive`: stream the regular files and folders of a tar archive (gzip, bzip2, xz or plain)
  into a private folder, capping the number of members, each member's size (by its role) and the total
  while decompressing; links, devices, FIFOs, sparse files and unsafe names are refused before anything of
  them is written. ``tarfile.extractall`` is never used.

Every refusal is an :class:`UnsafeInputError` (a ``ValueError``) naming the file, the problem and the fix.

This module imports nothing else of dv2s-gym.
"""

from __future__ import annotations

import bz2
import errno
import gzip
import json
import lzma
import os
import re
import stat
import tarfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Union

from scenario_bank.errors import DV2SError

__all__ = [
    "ENTRY_NAME_PATTERN",
    "nests_deeper_than",
    "UnsafeInputError",
    "ArchiveLimits",
    "validate_entry_name",
    "validate_relative_path",
    "is_entry_name",
    "read_regular_file",
    "read_in_folder",
    "regular_file_in_folder",
    "real_folder_in",
    "load_json_bounded",
    "extract_archive",
]

PathLike = Union[str, os.PathLike]

ENTRY_NAME_PATTERN = r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,127}"
"""The one pattern for a name in a bank: an entry folder, an archive member's path part, a file of an entry."""
_ENTRY_NAME = re.compile(ENTRY_NAME_PATTERN)
_MAX_PARTS = 8
_CHUNK = 1 << 16
_OPEN_FLAGS = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | getattr(os, "O_NOCTTY", 0)
_DIR_FLAGS = os.O_RDONLY | os.O_NOFOLLOW | os.O_DIRECTORY | os.O_CLOEXEC


class UnsafeInputError(DV2SError, ValueError):
    """A bank file, folder, name or archive is malformed or hostile; nothing was written."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _shown(name: Any) -> str:
    """``name`` for a message: quoted and escaped, at most 80 characters."""
    text = repr(name)
    return text if len(text) <= 80 else text[:77] + "..."


def is_entry_name(name: Any) -> bool:
    """Whether ``name`` matches :data:`ENTRY_NAME_PATTERN` and holds no ``..``."""
    return isinstance(name, str) and _ENTRY_NAME.fullmatch(name) is not None and ".." not in name


def validate_entry_name(name: Any, what: str = "entry name") -> str:
    """``name`` if it is a safe single name (:data:`ENTRY_NAME_PATTERN`, no ``..``, ``/``, NUL or newline),
    else an :class:`UnsafeInputError` naming ``what`` and the rule."""
    if not is_entry_name(name):
        raise UnsafeInputError(
            f"invalid {what} {_shown(name)}: a name in a bank is 1 to 128 letters, digits, '_', '-' and '.', "
            "not starting with '.' or '-', without '..', '/', spaces or control characters; rename it")
    return name


def validate_relative_path(path: Any, what: str = "entry file") -> str:
    """``path`` if it is a relative path of at most 8 parts, each a safe name (:func:`validate_entry_name`),
    else an :class:`UnsafeInputError`."""
    parts = path.split("/") if isinstance(path, str) else None
    if not parts or len(parts) > _MAX_PARTS or not all(is_entry_name(p) for p in parts):
        raise UnsafeInputError(
            f"invalid {what} {_shown(path)}: use a relative path of at most {_MAX_PARTS} parts separated by '/', "
            "each of letters, digits, '_', '-' and '.' (not starting with '.', no '..', not absolute)")
    return path


def _read_fd(fd: int, max_bytes: int, shown: str) -> bytes:
    """Read an open regular file, refusing it when it holds more than ``max_bytes``."""
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        raise UnsafeInputError(f"{shown} is {_kind(info.st_mode)}, not a regular file; replace it by a regular file")
    chunks: List[bytes] = []
    size = 0
    while size <= max_bytes:
        chunk = os.read(fd, min(_CHUNK, max_bytes + 1 - size))
        if not chunk:
            break
        chunks.append(chunk)
        size += len(chunk)
    if size > max_bytes:
        raise UnsafeInputError(f"{shown} is larger than {max_bytes} bytes, the limit for this file; "
                               "it cannot be a bank file: remove or shorten it")
    return b"".join(chunks)


def _open_error(error: OSError, shown: str) -> Exception:
    if error.errno == errno.ELOOP:
        return UnsafeInputError(f"{shown} is a symbolic link; bank files must be regular files inside the bank: "
                                "replace the link by a copy of the file")
    if error.errno == errno.ENOTDIR:
        return UnsafeInputError(f"{shown}: a part of its path is not a folder (or is a symbolic link to one); "
                                "bank folders must be real folders")
    return error


def read_regular_file(path: PathLike, max_bytes: int, *, follow_symlinks: bool = False) -> bytes:
    """The bytes of ``path``, a regular file of at most ``max_bytes`` bytes.

    The last part of ``path`` is not followed if it is a symbolic link (unless ``follow_symlinks``: a file
    the user named), a FIFO or a device is refused without blocking, and the type is checked on the opened
    descriptor. Raises :class:`UnsafeInputError` for those, ``FileNotFoundError`` (an ``OSError``) if it
    does not exist.
    """
    try:
        fd = os.open(path, _OPEN_FLAGS & ~os.O_NOFOLLOW if follow_symlinks else _OPEN_FLAGS)
    except OSError as error:
        raise _open_error(error, str(path)) from None
    try:
        return _read_fd(fd, max_bytes, str(path))
    finally:
        os.close(fd)


def _open_under(folder: PathLike, relative: str, last_flags: int) -> int:
    """A descriptor of ``folder/relative`` opened part by part, no part followed if it is a symbolic link."""
    parts = validate_relative_path(relative, "path inside the bank").split("/")
    shown = os.path.join(str(folder), relative)
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)  # the folder itself, as the user named it
    except OSError as error:
        raise _open_error(error, str(folder)) from None
    try:
        for k, part in enumerate(parts):
            flags = last_flags if k == len(parts) - 1 else _DIR_FLAGS
            try:
                child = os.open(part, flags, dir_fd=fd)
            except OSError as error:
                raise _open_error(error, shown) from None
            os.close(fd)
            fd = child
        return fd
    except BaseException:
        os.close(fd)
        raise


def read_in_folder(folder: PathLike, relative: str, max_bytes: int) -> bytes:
    """The bytes of ``folder/relative`` (:func:`read_regular_file`), where no part of ``relative`` may be a
    symbolic link: a folder of the bank swapped for a link to elsewhere is refused, not followed."""
    fd = _open_under(folder, relative, _OPEN_FLAGS)
    try:
        return _read_fd(fd, max_bytes, os.path.join(str(folder), relative))
    finally:
        os.close(fd)


def regular_file_in_folder(folder: PathLike, relative: str) -> bool:
    """Whether ``folder/relative`` is a regular file reached without following symbolic links (never blocks)."""
    try:
        fd = _open_under(folder, relative, _OPEN_FLAGS)
    except (OSError, UnsafeInputError):
        return False
    try:
        return stat.S_ISREG(os.fstat(fd).st_mode)
    finally:
        os.close(fd)


def real_folder_in(folder: PathLike, relative: str) -> bool:
    """Whether ``folder/relative`` is a folder reached without following symbolic links, or does not exist
    yet with every existing part a real folder: what a writer may create files under."""
    current = Path(folder)
    for part in validate_relative_path(relative, "path inside the bank").split("/"):
        current = current / part
        try:
            mode = os.lstat(current).st_mode
        except FileNotFoundError:
            return True
        if not stat.S_ISDIR(mode):
            return False
    return True


def nests_deeper_than(text: str, max_depth: int) -> bool:
    """Whether the brackets of JSON ``text`` (outside strings) nest deeper than ``max_depth``; one pass, no
    recursion, stopping at the first too deep bracket."""
    depth = 0
    in_string = False
    for match in re.finditer(r'[\[\]{}"\\]', text):
        char = match.group()
        if in_string:
            if char == "\\":
                continue  # the escaped character is skipped below
            if char == '"' and not _escaped(text, match.start()):
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            if depth > max_depth:
                return True
        elif char in "]}":
            depth -= 1
    return False


def _escaped(text: str, index: int) -> bool:
    """Whether the character at ``index`` is preceded by an odd number of backslashes."""
    count = 0
    while index > 0 and text[index - 1] == "\\":
        count += 1
        index -= 1
    return count % 2 == 1


def load_json_bounded(data: bytes, max_depth: int = 64, what: str = "JSON file") -> Any:
    """``data`` (UTF-8 JSON, already size-capped by its reader) parsed, refusing more than ``max_depth``
    nested arrays and objects before :func:`json.loads` sees it. Raises :class:`UnsafeInputError`."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise UnsafeInputError(f"{what} is not UTF-8 text ({error.reason} at byte {error.start}); "
                               "rewrite it as UTF-8 JSON") from None
    if nests_deeper_than(text, max_depth):
        raise UnsafeInputError(f"{what} nests arrays and objects deeper than {max_depth} levels; "
                               "it cannot be a bank file: rewrite it")
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as error:
        raise UnsafeInputError(f"{what} is not valid JSON: {error}; fix or replace it") from None


# ---------------------------------------------------------------- archives
@dataclass(frozen=True)
class ArchiveLimits:
    """Caps applied while an archive is decompressed, before more than the cap is read or written."""

    max_members: int = 10_000
    """Members (files, folders and extended headers count once each per member)."""
    max_total_bytes: int = 256 << 20
    """Bytes of all member data together."""
    max_file_bytes: int = 64 << 20
    """Bytes of one file an entry carries (e.g. a failure video)."""
    max_script_bytes: int = 1 << 20
    """Bytes of one ``scenario.scenic``."""
    max_sidecar_bytes: int = 1 << 20
    """Bytes of one ``meta.json`` or of the archive's header."""
    max_header_bytes: int = 64 << 10
    """Bytes of one extended tar header (long names, pax records)."""


class _Bounded:
    """A read-only stream that refuses to return more than ``limit`` bytes of ``raw`` (the decompressed tar)."""

    def __init__(self, raw: Any, limit: int, archive: str) -> None:
        self.raw, self.limit, self.archive, self.done = raw, limit, archive, 0

    def read(self, size: int = -1) -> bytes:
        if size is None or size < 0:
            size = self.limit + 1 - self.done
        data = self.raw.read(min(size, self.limit + 1 - self.done))
        self.done += len(data)
        if self.done > self.limit:
            raise UnsafeInputError(f"{self.archive} decompresses to more than {self.limit} bytes; refusing to import "
                                   "it (split it into smaller archives, or raise the limit if you trust it)")
        return data


def _tarinfo_class(limits: ArchiveLimits, archive: str) -> type:
    class BoundedTarInfo(tarfile.TarInfo):
        """A member header whose extended headers (long names, pax records) are capped before they are read."""

        _chain = 0

        def _proc_member(self, tar):  # noqa: ANN001 - tarfile's own hook
            extended = self.type in (tarfile.GNUTYPE_LONGNAME, tarfile.GNUTYPE_LONGLINK, tarfile.XHDTYPE,
                                     tarfile.XGLTYPE, tarfile.SOLARIS_XHDTYPE)
            if not extended:
                return super()._proc_member(tar)
            if self.size > limits.max_header_bytes:
                raise UnsafeInputError(f"{archive} holds an extended tar header of {self.size} bytes (the limit is "
                                       f"{limits.max_header_bytes}); it is not a bank archive written by `dv2s bank "
                                       "export`")
            cls = type(self)
            if cls._chain >= 8:  # tarfile reads chained extended headers by recursion
                raise UnsafeInputError(f"{archive} chains more than 8 extended tar headers; it is not a bank archive "
                                       "written by `dv2s bank export`")
            cls._chain += 1
            try:
                return super()._proc_member(tar)
            finally:
                cls._chain -= 1

    return BoundedTarInfo


def _decompressed(handle: Any) -> Any:
    """``handle`` (a file opened in binary mode) as a stream of the tar bytes inside, by its magic bytes."""
    magic = handle.read(6)
    handle.seek(0)
    if magic.startswith(b"\x1f\x8b"):
        return gzip.GzipFile(fileobj=handle, mode="rb")
    if magic.startswith(b"BZh"):
        return bz2.BZ2File(handle, mode="rb")
    if magic.startswith(b"\xfd7zXZ\x00"):
        return lzma.LZMAFile(handle, mode="rb")
    return handle


def _member_kind(member: tarfile.TarInfo) -> str:
    if member.issym():
        return "a symbolic link"
    if member.islnk():
        return "a hard link"
    if member.ischr() or member.isblk():
        return "a device"
    if member.isfifo():
        return "a FIFO"
    if member.type == tarfile.GNUTYPE_SPARSE or getattr(member, "sparse", None) is not None:
        return "a sparse file"
    if member.type == tarfile.CONTTYPE:
        return "a contiguous file"
    return f"of tar type {member.type!r}"


def extract_archive(archive: PathLike, dest: PathLike, member_cap: Callable[[str], int],
                    limits: ArchiveLimits = ArchiveLimits()) -> Dict[str, int]:
    """Stream the members of a tar archive into ``dest`` (an empty, private folder); returns name -> size.

    Only regular files and folders whose every path part is a safe name (:func:`validate_relative_path`) are
    accepted; one other member is an :class:`UnsafeInputError` and the caller discards ``dest``. Each file is
    written as it is decompressed and stops at ``member_cap(name)`` + 1 byte (never trusting the sizes its
    header claims); the member count, the total and the extended headers are capped by ``limits``. Files are
    created exclusively (a name given twice is refused) and without following links.
    """
    archive = str(archive)
    dest = Path(dest)
    sizes: Dict[str, int] = {}
    total = 0
    fd = os.open(archive, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # a FIFO given as the archive never blocks
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise UnsafeInputError(f"{archive} is {_kind(mode)}, not an archive file; pass the .tar.gz written by "
                               "`dv2s bank export`")
    with os.fdopen(fd, "rb") as handle:
        # the decompressed stream may hold headers and padding besides the member data
        budget = limits.max_total_bytes + (limits.max_members + 2) * 3 * tarfile.BLOCKSIZE + limits.max_header_bytes
        stream = _Bounded(_decompressed(handle), budget, archive)
        with tarfile.open(fileobj=stream, mode="r|", tarinfo=_tarinfo_class(limits, archive)) as tar:
            count = 0
            for member in tar:
                count += 1
                if count > limits.max_members:
                    raise UnsafeInputError(f"{archive} holds more than {limits.max_members} members; refusing to "
                                           "import it (split it into smaller archives)")
                name = member.name
                if not (member.isdir() or member.type in (tarfile.REGTYPE, tarfile.AREGTYPE)) \
                        or getattr(member, "sparse", None) is not None:
                    raise UnsafeInputError(f"{archive} holds member {_shown(name)}, which is {_member_kind(member)}; "
                                           "a bank archive holds only regular files and folders: refusing to import it")
                validate_relative_path(name, f"member name in {archive}")
                if member.isdir():
                    _make_dirs(dest, name)
                    continue
                size = _stream_member(tar, member, dest, name, member_cap(name), limits.max_total_bytes - total,
                                      archive)
                total += size
                sizes[name] = size
    return sizes


def _make_dirs(dest: Path, relative: str) -> Path:
    """``dest/relative`` created as real folders (``dest`` is the private extraction folder)."""
    current = dest
    for part in relative.split("/"):
        current = current / part
        try:
            os.mkdir(current, 0o700)
        except FileExistsError:
            if not stat.S_ISDIR(os.lstat(current).st_mode):
                raise UnsafeInputError(f"archive member {_shown(relative)} needs {part!r} to be a folder, but the "
                                       "archive also holds it as a file; it is not a bank archive") from None
    return current


def _stream_member(tar: tarfile.TarFile, member: tarfile.TarInfo, dest: Path, name: str, cap: int, budget: int,
                   archive: str) -> int:
    """Copy one member's data to ``dest/name`` in chunks, refusing it past ``cap`` bytes or past ``budget``
    (what is left of the archive's total); returns its size."""
    folder, _, base = name.rpartition("/")
    target = (_make_dirs(dest, folder) if folder else dest) / base
    if member.size > cap:
        raise UnsafeInputError(f"{archive}: member {_shown(name)} is larger than {cap} bytes, the limit for this "
                               "file; refusing to import it")
    too_much = UnsafeInputError(f"{archive} holds more files than the limit of its total size; refusing to "
                                "import it (split it into smaller archives)")
    if member.size > budget:
        raise too_much
    source = tar.extractfile(member)
    try:
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    except FileExistsError:
        raise UnsafeInputError(f"{archive} holds member {_shown(name)} twice (or as a folder too); it is not a "
                               "bank archive written by `dv2s bank export`") from None
    out = os.fdopen(fd, "wb")
    size = 0
    try:
        while True:
            chunk = source.read(min(_CHUNK, min(cap, budget) + 1 - size)) if source is not None else b""
            if not chunk:
                break
            size += len(chunk)
            if size > budget:
                raise too_much
            if size > cap:
                raise UnsafeInputError(f"{archive}: member {_shown(name)} is larger than {cap} bytes, the limit for "
                                       "this file; refusing to import it")
            out.write(chunk)
    finally:
        out.close()
    return size
