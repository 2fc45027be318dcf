"""Hostile bank folders, as an attacker would leave them in a bank someone else opens.

Each builder of :data:`FOLDERS` plants one entry, ``evil`` (or a folder whose name is the attack), in an
existing bank folder next to its good entries. :data:`FOLDERS` maps a builder's name to
``(builder, what the error or problem line says)``. ``secret`` is a file outside the bank whose text must
never be printed; ``outside`` a folder outside the bank that must stay unchanged.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Callable, Dict, Tuple

SCRIPT = "param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n"
SECRET = "DV2S-HOSTILE-SECRET-CANARY"


def sidecar(name: str = "evil", script: str = SCRIPT, **source: object) -> str:
    return json.dumps({"schema_version": 1, "name": name, "description": "hostile", "map": "highway_straight",
                       "tags": [], "elements": {}, "source": {"kind": "hand-written", **source},
                       "content_hash": hashlib.sha256(script.encode()).hexdigest()})


def _entry(root: Path, name: str = "evil", meta: str = None, script: str = SCRIPT) -> Path:
    folder = root / name
    folder.mkdir()
    if meta is not False:
        (folder / "meta.json").write_text(sidecar(name) if meta is None else meta)
    if script is not None:
        (folder / "scenario.scenic").write_text(script)
    return folder


def fifo_meta(root: Path, secret: Path, outside: Path) -> None:
    folder = _entry(root, meta=False)
    os.mkfifo(folder / "meta.json")


def fifo_script(root: Path, secret: Path, outside: Path) -> None:
    folder = _entry(root, script=None)
    os.mkfifo(folder / "scenario.scenic")


def symlinked_script(root: Path, secret: Path, outside: Path) -> None:
    # the sidecar's hash matches the secret: only the link itself can give it away
    folder = _entry(root, meta=sidecar(script=secret.read_text()), script=None)
    os.symlink(secret, folder / "scenario.scenic")


def symlinked_meta(root: Path, secret: Path, outside: Path) -> None:
    folder = _entry(root, meta=False)
    (outside / "meta.json").write_text(sidecar())
    os.symlink(outside / "meta.json", folder / "meta.json")


def symlinked_entry(root: Path, secret: Path, outside: Path) -> None:
    _entry(outside, "linked", meta=sidecar("linked", script=secret.read_text()), script=secret.read_text())
    os.symlink(outside / "linked", root / "evil")


def traversal_folder_name(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, "evil..name")


def newline_folder_name(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, "evil\n! good: forged line")


def nested_meta(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, meta="[" * 100_000 + "]" * 100_000)


def huge_meta(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, meta='{"description": "' + " " * (4 << 20) + '"}')


def meta_files_outside(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, meta=sidecar(files=[f"../../{secret.parent.name}/{secret.name}"]))


def meta_merged_files_absolute(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, meta=sidecar(merged=[{"kind": "mined", "files": [str(secret)]}]))


def symlinked_entry_file(root: Path, secret: Path, outside: Path) -> None:
    folder = _entry(root, meta=sidecar(files=["failure.webm"]))
    os.symlink(secret, folder / "failure.webm")


def meta_name_traversal(root: Path, secret: Path, outside: Path) -> None:
    _entry(root, meta=json.dumps({**json.loads(sidecar()), "name": "../../escape"}))


FOLDERS: Dict[str, Tuple[Callable[[Path, Path, Path], None], str]] = {
    "fifo_meta": (fifo_meta, "is a FIFO"),
    "fifo_script": (fifo_script, "not a regular file"),
    "symlinked_script": (symlinked_script, "not a regular file"),
    "symlinked_meta": (symlinked_meta, "is a symbolic link"),
    "symlinked_entry": (symlinked_entry, "symbolic link to a folder"),
    "traversal_folder_name": (traversal_folder_name, "not a valid entry name"),
    "newline_folder_name": (newline_folder_name, "not a valid entry name"),
    "nested_meta": (nested_meta, "deeper than"),
    "huge_meta": (huge_meta, "larger than"),
    "meta_files_outside": (meta_files_outside, "not a file inside the entry"),
    "meta_merged_files_absolute": (meta_merged_files_absolute, "not a file inside the entry"),
    "symlinked_entry_file": (symlinked_entry_file, None),  # a usable entry whose linked file is never read
    "meta_name_traversal": (meta_name_traversal, "not a valid entry name"),
}
"""name -> (builder, what the problem says; None: the entry stays usable, the linked file counts as missing)."""
