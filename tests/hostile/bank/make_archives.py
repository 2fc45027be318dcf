"""Write the hostile bank archives of this folder (``*.tar.gz``, ``*.tar``), as an attacker would craft them.

Run ``python tests/hostile/bank/make_archives.py`` to rebuild them; the output is deterministic. Each
archive imitates a bank archive (a ``bank-archive.json`` header, ``<entry>/meta.json`` and
``<entry>/scenario.scenic``) around one attack. :data:`ARCHIVES` names each file with what the import must
refuse (a substring of the one-line error). Absolute and ``..`` names aim at :data:`ESCAPE`, which must
never appear.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import sys
import tarfile
from pathlib import Path
from typing import Callable, Dict, List, Tuple

HERE = Path(__file__).resolve().parent
ESCAPE = "/tmp/dv2s-hostile-bank-escape"
"""Where the absolute and traversal names of these archives point; a test fails if it exists afterwards."""

SCRIPT = b"param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n"


def sidecar(name: str = "x", **source: object) -> bytes:
    """A well-formed sidecar for :data:`SCRIPT` (``source`` fields added)."""
    return json.dumps({"schema_version": 1, "name": name, "description": "hostile", "map": "highway_straight",
                       "tags": [], "elements": {}, "source": {"kind": "hand-written", **source},
                       "content_hash": hashlib.sha256(SCRIPT).hexdigest()}).encode()


def header(*entries: str) -> Tuple[str, bytes]:
    return "bank-archive.json", json.dumps({"dv2s_bank_archive": 1, "entries": list(entries)}).encode()


class _Zeros(io.RawIOBase):
    """``size`` zero bytes, produced as read (nothing that size is ever held in memory)."""

    def __init__(self, size: int) -> None:
        self.left = size

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = min(len(buffer), self.left)
        buffer[:n] = bytes(n)
        self.left -= n
        return n


def _info(name: str, size: int = 0, kind: bytes = tarfile.REGTYPE, **fields: object) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.size, info.type, info.mtime, info.mode = size, kind, 0, 0o644
    for key, value in fields.items():
        setattr(info, key, value)
    return info


def write(path: Path, members: List[tuple], fmt: int = tarfile.GNU_FORMAT) -> None:
    """A tar archive at ``path`` (gzip-compressed for ``.gz``, mtime 0) of ``members``: ``(name, bytes)``,
    ``(TarInfo, bytes or None)`` or ``(TarInfo, reader)``."""
    raw = io.BytesIO()
    with tarfile.open(fileobj=raw, mode="w", format=fmt) as tar:
        for name, data in members:
            info = name if isinstance(name, tarfile.TarInfo) else _info(name, len(data))
            if isinstance(data, bytes):
                info.size = len(data)
                data = io.BytesIO(data)
            tar.addfile(info, data)
    payload = raw.getvalue()
    if path.suffix == ".gz":
        payload = gzip.compress(payload, compresslevel=9, mtime=0)
    path.write_bytes(payload)


def entry(name: str = "x", meta: bytes = None, script: bytes = SCRIPT) -> List[tuple]:
    return [(f"{name}/meta.json", sidecar(name) if meta is None else meta), (f"{name}/scenario.scenic", script)]


def _gzip_bomb(path: Path) -> None:
    # 64 MiB of zeros as a script (1 MiB cap): the archive is ~64 KB
    write(path, [header("x"), ("x/meta.json", sidecar()), (_info("x/scenario.scenic", 64 << 20), _Zeros(64 << 20))])


def _file_bomb(path: Path) -> None:
    # 5 entry files of 60 MiB each, each under the per-file cap (64 MiB), together over the total (256 MiB)
    files = [f"f{k}.bin" for k in range(5)]
    members = [header("x"), ("x/meta.json", sidecar(files=files)), ("x/scenario.scenic", SCRIPT)]
    members += [(_info(f"x/{f}", 60 << 20), _Zeros(60 << 20)) for f in files]
    write(path, members)


def _many_members(path: Path) -> None:
    write(path, [header("x")] + entry() + [(f"x/m{k}", b"") for k in range(10_050)])


def _pax_header_bomb(path: Path) -> None:
    # one extended (pax) header of 8 MiB, read by tarfile into memory before the member it describes
    info = _info("x/scenario.scenic", len(SCRIPT))
    info.pax_headers = {"comment": "A" * (8 << 20)}
    write(path, [header("x"), ("x/meta.json", sidecar()), (info, SCRIPT)], fmt=tarfile.PAX_FORMAT)


def _chained_pax_headers(path: Path) -> None:
    # 2000 extended headers in a row: tarfile reads each by recursion (a RecursionError without a cap)
    record = b"13 comment=x\n"
    chain = [(_info("././@PaxHeader", kind=tarfile.XHDTYPE), record) for _ in range(2000)]
    write(path, [header("x")] + chain + entry())


ARCHIVES: Dict[str, Tuple[str, Callable[[Path], None]]] = {
    "gzip_bomb.tar.gz": ("larger than", _gzip_bomb),
    "total_size_bomb.tar.gz": ("limit of its total size", _file_bomb),
    "many_members.tar.gz": ("more than 10000 members", _many_members),
    "pax_header_bomb.tar.gz": ("extended tar header", _pax_header_bomb),
    "chained_pax_headers.tar.gz": ("chains more than 8 extended tar headers", _chained_pax_headers),
    "absolute_member.tar.gz": ("invalid member name", lambda p: write(p, [header("x")] + entry() + [
        (f"{ESCAPE}/pwned", b"escaped")])),
    "dotdot_member.tar.gz": ("invalid member name", lambda p: write(p, [header("x")] + entry() + [
        ("x/../../dv2s-hostile-bank-escape/pwned", b"escaped")])),
    "absolute_header_entry.tar.gz": ("invalid entry name", lambda p: write(p, [header(ESCAPE)] + entry())),
    "dotdot_header_entry.tar.gz": ("invalid entry name", lambda p: write(p, [header("../dv2s-hostile-bank-escape")]
                                                                             + entry())),
    "symlink_member.tar.gz": ("symbolic link", lambda p: write(p, [header("x"), ("x/meta.json", sidecar()), (
        _info("x/scenario.scenic", kind=tarfile.SYMTYPE, linkname="/etc/passwd"), None)])),
    "hardlink_member.tar.gz": ("hard link", lambda p: write(p, [header("x"), ("x/meta.json", sidecar()), (
        _info("x/scenario.scenic", kind=tarfile.LNKTYPE, linkname="/etc/passwd"), None)])),
    "device_member.tar.gz": ("device", lambda p: write(p, [header("x")] + entry() + [(
        _info("x/zero", kind=tarfile.CHRTYPE, devmajor=1, devminor=5), None)])),
    "fifo_member.tar.gz": ("FIFO", lambda p: write(p, [header("x"), ("x/meta.json", sidecar()), (
        _info("x/scenario.scenic", kind=tarfile.FIFOTYPE), None)])),
    "nul_in_name.tar": ("invalid member name", lambda p: write(p, [header("x")] + entry() + [
        (_info("x/evil", pax_headers={"path": "x/evil\x00/../../escape"}), b"x")], fmt=tarfile.PAX_FORMAT)),
    "newline_in_name.tar.gz": ("invalid member name", lambda p: write(p, [header("x")] + entry() + [
        ("x/evil\nline", b"x")])),
    "nested_meta.tar.gz": ("deeper than", lambda p: write(p, [header("x")] + entry(
        meta=b"[" * 100_000 + b"]" * 100_000))),
    "huge_meta.tar.gz": ("larger than", lambda p: write(p, [header("x")] + entry(
        meta=b'{"description": "' + b" " * (4 << 20) + b'"}'))),
    "meta_files_outside.tar.gz": ("not a file inside the entry", lambda p: write(p, [header("x")] + entry(
        meta=sidecar(files=["../../../etc/passwd"])))),
    "meta_merged_files_absolute.tar.gz": ("not a file inside the entry", lambda p: write(p, [header("x")] + entry(
        meta=sidecar(merged=[{"kind": "mined", "files": ["/etc/passwd"]}])))),
    "duplicate_member.tar.gz": ("twice", lambda p: write(p, [header("x")] + entry() + [
        ("x/scenario.scenic", b"swapped")])),
    "stray_member.tar.gz": ("belongs to no entry", lambda p: write(p, [header("x")] + entry() + entry("y"))),
    "nested_header.tar.gz": ("deeper than", lambda p: write(p, [
        ("bank-archive.json", b"[" * 100_000 + b"]" * 100_000)] + entry())),
}


def main() -> None:
    for name, (_, build) in ARCHIVES.items():
        build(HERE / name)
        print(f"{name}: {(HERE / name).stat().st_size} bytes", file=sys.stderr)


if __name__ == "__main__":
    main()
