"""What user code reads while a run runs: the Python modules it imports and the data files it opens for reading.

A plug-in detector whose threshold sits in a JSON file beside it, or that imports a helper module only inside
``detect`` (so only the worker processes ever import it), decides what a run counts as much as its own source. A
process that calls :func:`watch` (a run when it starts, every worker process before it imports the plug-ins) notes
every file opened for reading, through one audit hook (:func:`sys.addaudithook`: the ``open`` event, a string
comparison for every other event); :func:`user_reads` then lists, with their SHA-256, the user's files among them
and the user's modules loaded in the process: everything but Python's installation (its prefixes, site-packages),
dv2s-gym's own packages (fingerprinted apart), dv2s's user cache, the system's folders (``/dev``, ``/proc``,
``/sys``, ``/etc``, ``/usr``, ...), the home folder's hidden folders (``~/.cache``, ``~/.config``), the temporary folder (but a folder on the Python path inside it) and the
folders a run names as its own (its run folder, its bank).

:func:`reading_for` labels what is read (and imported for the first time) inside it, such as
``"detector speeding"`` while a plug-in's detector judges an episode, or ``"plug-in myfail"`` while a plug-in
module is imported, so a report can say which files decided a failure kind.
"""

from __future__ import annotations

import os
import site
import sys
import sysconfig
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterable, Iterator, List, Optional, Set, Tuple

from scenario_bank.atomic import file_sha256
from scenario_bank.cache import cache_dir
from scenario_bank.errors import DV2SError

__all__ = ["ReadFile", "ReadFilesError", "watch", "reading_for", "user_reads", "unsent_reads", "detector_label",
           "plugin_label", "labelled_module", "unwatched", "changed_while_running", "DV2S_ROOT", "DV2S_PACKAGES", "python_roots", "python_path_folders", "SYSTEM_FOLDERS"]

DV2S_ROOT = Path(__file__).resolve().parents[1]
"""The folder holding dv2s-gym's four packages."""
DV2S_PACKAGES = ("envs", "dv2s_gym", "policies", "scenario_bank")
SYSTEM_FOLDERS = ("/dev", "/proc", "/sys", "/etc", "/usr", "/lib", "/lib64", "/bin", "/sbin", "/run", "/var",
                  "/opt/conda")
"""Folders of the system whose files are no user's code or data."""
_SKIPPED_PARTS = {"__pycache__", "site-packages", "dist-packages", "node_modules"}
_METADATA_SUFFIXES = (".egg-info", ".dist-info")
"""Folders of installed distributions' metadata (an editable install writes one beside the sources): read when a
version is looked up, never code or data of a run."""


@dataclass(frozen=True)
class ReadFile:
    """One user file a process read: its absolute ``path``, the ``module`` whose source it is (``None`` for a data
    file), its ``sha256`` when read and the ``labels`` of the :func:`reading_for` blocks that read it."""

    path: str
    module: Optional[str]
    sha256: str
    labels: Tuple[str, ...] = ()


class ReadFilesError(DV2SError, ValueError):
    """The user's files a run read cannot stand for what it did: one changed while the run ran (its episodes would
    mix two versions of it), or two different SHA-256 would be recorded under one file's name."""


def changed_while_running(path: str, recorded: str, now: str) -> ReadFilesError:
    """The error for a file the run read that changed while it ran, naming the file, both SHA-256 and the fix."""
    return ReadFilesError(f"{path} changed while the run ran (SHA-256 {recorded[:12]} -> {now[:12]}), so its "
                          "episodes would be judged by two versions of it; the run stopped, keeping the episodes "
                          "it finished: restore the file and resume (rerun the same command)")


_installed = False
_opened: Dict[str, Set[str]] = {}  # absolute path -> labels of the blocks that opened it
_module_labels: Dict[str, Set[str]] = {}  # module name -> labels of the blocks that imported it first
_scopes: List[str] = []
_known_modules: Set[str] = set()
_hashes: Dict[str, Tuple[int, int, str]] = {}  # path -> (mtime_ns, size, SHA-256)
_sent: Dict[str, Tuple[str, Tuple[str, ...]]] = {}  # path -> (SHA-256, labels) given by unsent_reads
_user_path: Dict[str, Optional[Path]] = {}  # a file's name as read -> its resolved path when the user's, else None


_quiet = [0]  # > 0 inside unwatched(): a file hashed for a run's identity is not a file the code read


def _hook(event: str, args: tuple) -> None:
    if event != "open" or _quiet[0]:
        return
    try:
        path, mode, flags = args
        if mode is None:  # os.open
            if flags & os.O_ACCMODE != os.O_RDONLY:
                return
        elif not mode.startswith("r") or "+" in mode:
            return
        if isinstance(path, int):
            return
        path = os.fsdecode(path)
        if path.endswith(".pyc"):  # an import: the module's source is found through sys.modules
            return
        if not path.startswith("/"):
            path = os.path.join(os.getcwd(), path)
        labels = _opened.setdefault(path, set())
        if _scopes:
            labels.add(_scopes[-1])
    except Exception:  # a watcher never breaks what it watches
        return


def watch() -> None:
    """Start noting the files this process opens for reading (once per process; an audit hook cannot be removed,
    and costs a string comparison per audit event)."""
    global _installed
    if not _installed:
        sys.addaudithook(_hook)
        _installed = True


@contextmanager
def unwatched() -> Iterator[None]:
    """Files opened inside the block are not noted: dv2s hashing a file to record or check it is not the code
    reading it (a check of a recorded ``limits.json`` would otherwise make it a file read outside any plug-in)."""
    _quiet[0] += 1
    try:
        yield
    finally:
        _quiet[0] -= 1


def detector_label(kind: str) -> str:
    """The :func:`reading_for` label of the detector of failure kind ``kind``."""
    return f"detector {kind}"


def plugin_label(module: str) -> str:
    """The :func:`reading_for` label of the import of plug-in module ``module``."""
    return f"plug-in {module}"


def labelled_module(label: str, detectors: Dict[str, str]) -> Optional[str]:
    """The module a :func:`reading_for` ``label`` names: the plug-in module it imported, or the module that
    registered the detector (``detectors``: failure kind -> module) it ran; ``None`` for another label."""
    role, _, name = label.partition(" ")
    if role == plugin_label("").strip():
        return name or None
    if role == detector_label("").strip():
        return detectors.get(name)
    return None


def _sync_modules() -> List[str]:
    """The module names loaded since the last call (cheap when none was: a length comparison)."""
    if len(sys.modules) == len(_known_modules):
        return []
    names = set(sys.modules)
    new = list(names - _known_modules)
    _known_modules.clear()
    _known_modules.update(names)
    return new


@contextmanager
def reading_for(label: str) -> Iterator[None]:
    """Label the files opened, and the modules imported for the first time, inside the block with ``label``."""
    _sync_modules()
    _scopes.append(label)
    try:
        yield
    finally:
        _scopes.pop()
        for name in _sync_modules():
            _module_labels.setdefault(name, set()).add(label)


def python_roots() -> List[Path]:
    """Where Python's installation lives: its prefixes, the standard library, site-packages, the scripts folder."""
    found = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix}
    found.update(value for key, value in sysconfig.get_paths().items() if value)
    found.update(site.getsitepackages() if hasattr(site, "getsitepackages") else [])
    user_site = site.getusersitepackages() if hasattr(site, "getusersitepackages") else None
    if isinstance(user_site, str):
        found.add(user_site)
    return sorted({Path(root).resolve() for root in found if root})


def _under(path: Path, roots: Iterable[Path]) -> bool:
    return any(path == root or root in path.parents for root in roots)


def python_path_folders() -> List[Path]:
    """The folders on the Python path that are not Python's installation (a plug-in folder, say)."""
    python = python_roots()
    found = []
    for entry in sys.path:
        folder = Path(entry or ".").resolve()
        if folder.is_dir() and not _under(folder, python) and folder not in found:
            found.append(folder)
    return found


def _is_user_file(path: Path, never: List[Path], python_path: List[Path]) -> bool:
    """Whether ``path`` is the user's: not Python's, dv2s's or the run's own (``never``), and either on the Python
    path or out of the system's and the temporary folders."""
    if _under(path, never) or _SKIPPED_PARTS & set(path.parts) or any(
            part.endswith(_METADATA_SUFFIXES) for part in path.parts):
        return False
    if _under(path, python_path):
        return True
    transient = [Path(folder) for folder in SYSTEM_FOLDERS] + [Path(tempfile.gettempdir()).resolve()]
    home = Path.home()
    if home in path.parents and path.relative_to(home).parts[0].startswith("."):
        return False  # the home folder's hidden folders: caches and settings of the libraries (~/.cache, ~/.config)
    return not _under(path, transient)


def _sha256(path: Path) -> Optional[str]:
    """The file's SHA-256 (remembered while its size and time stay), ``None`` when it is no longer a file."""
    try:
        stat = path.stat()
    except OSError:
        return None
    key = str(path)
    known = _hashes.get(key)
    if known is not None and known[:2] == (stat.st_mtime_ns, stat.st_size):
        return known[2]
    if not path.is_file():
        return None
    with unwatched():
        digest = file_sha256(path)
    _hashes[key] = (stat.st_mtime_ns, stat.st_size, digest)
    return digest


def _user_file(name: str, never: List[Path], python_path: List[Path]) -> Optional[Path]:
    """The resolved path of the file read as ``name`` when it is the user's (remembered: the same answer for every
    task of a worker), else ``None``."""
    if name not in _user_path:
        path = Path(name).resolve()
        _user_path[name] = path if _is_user_file(path, never, python_path) else None
    return _user_path[name]


def user_reads(exclude: Iterable[os.PathLike | str] = ()) -> Dict[str, ReadFile]:
    """The user's files this process read (module docstring): every user module loaded (its source file) and every
    user file opened for reading since :func:`watch`, by absolute path; none under a folder of ``exclude``."""
    for name in _sync_modules():  # modules imported outside any block: no label, but known from now on
        _module_labels.setdefault(name, set())
    never = python_roots() + [DV2S_ROOT / package for package in DV2S_PACKAGES] + [cache_dir().resolve()]
    python_path = python_path_folders()
    excluded = [Path(folder).resolve() for folder in exclude if folder]
    found: Dict[str, ReadFile] = {}
    for name, module in list(sys.modules.items()):
        file = getattr(module, "__file__", None)
        path = _user_file(file, never, python_path) if file and str(file).endswith(".py") else None
        digest = _sha256(path) if path is not None and not _under(path, excluded) else None
        if digest is not None:
            found[str(path)] = ReadFile(str(path), name, digest, tuple(sorted(_module_labels.get(name, ()))))
    for opened, labels in list(_opened.items()):
        path = _user_file(opened, never, python_path)
        if path is None or str(path) in found or _under(path, excluded):
            continue
        digest = _sha256(path)
        if digest is not None:
            found[str(path)] = ReadFile(str(path), None, digest, tuple(sorted(labels)))
    return found


def unsent_reads() -> List[ReadFile]:
    """The :func:`user_reads` not given by an earlier call, read since under a new label, or whose SHA-256 changed
    since (what a worker process sends with a task's result)."""
    new = []  # every file is looked at again (a stat each): one edited since it was sent is sent again
    for path, read in user_reads().items():
        if _sent.get(path) != (read.sha256, read.labels):
            _sent[path] = (read.sha256, read.labels)
            new.append(read)
    return new
