"""The policy half of a resumable run's identity: what a resumed run must find unchanged in its policy.

The settings half is :mod:`scenario_bank.run_identity` (the recorded settings compared with the asked ones); this
module gives, for a policy spec, the facts that decide how the policy drives (:func:`resume_fingerprint`):

- a checkpoint (``model.zip``, ``ppo:PATH``, a folder, the shipped ``dv2s-ppo``): the SHA-256 of its bytes (and of
  the model card beside it);
- ``module:attribute``: the SHA-256 of the module's source file, and of the user's own modules the policy may use:
  every ``.py`` file beside it (its package's tree when it is in a package; at most :data:`MAX_HELPER_FILES`), and
  every module loaded in this process whose file is the user's code, wherever it lives (a ``lib/`` folder on the
  Python path, an editable install of the user's package, the script run as ``__main__``): all but the standard
  library, site-packages (and dist-packages), the environment's scripts folder and dv2s's own packages;
- a registered driver (``rule``, ``idm``, ...): the SHA-256 of the module that implements it;
- the spec's options, typed and sorted, and the bytes (SHA-256) of every option value that names an existing file
  (``?weights=weights.json``), and the dv2s version.

``dv2s mine``, ``dv2s loop`` and ``dv2s regress`` record them when a run starts and refuse, with
:func:`check_policy_unchanged`, to resume it when the same spec now names a changed checkpoint or module. A loaded
module's file is compared as the run recorded it: each file the run recorded is hashed again (edited or deleted
since, the resume is refused), and a module this process loaded that the run did not have loaded is not compared
(a notebook's own helpers, say), as it cannot have decided what the run did before. (A DAgger
fine-tuning records its source checkpoint's SHA-256 among its settings; a PPO fine-tuning copies the checkpoint
into its run folder first.)

The code half is :func:`code_identity`, recorded by every resumable run kind under :data:`CODE_IDENTITY` and checked
by :func:`check_code_unchanged`: one SHA-256 over dv2s's own sources (every ``.py`` file of its four packages, so
an edited editable install is noticed), the plug-in modules loaded in this process (``DV2S_PLUGINS``, those of
every registered failure type, detector and policy, and those that registered a sampler or a DRA/SG backend,
:func:`scenario_bank.plugins.code_modules`; a registration in ``__main__`` by the script's file, when it has one)
with the fingerprints of their source (as a ``module:attribute`` policy's), what they registered (failure type or
detector name -> module), the built-in entries they replaced, and the user's files the code read
(:mod:`scenario_bank.read_files`: modules imported and data files opened, in this process and, added as the run goes
by :class:`ReadsRecorder`, in its workers; :func:`read_facts`). A user's file is named so that moving the folder
holding it with the Python path keeps its name: a module by its module name; a file a plug-in module read (while
it was imported or its detector ran), or a ``.py`` file beside a fingerprinted module, by its path relative to that
module's folder and the module's name (``user file limits.json read by myfail``: two plug-ins' ``limits.json`` are
two names, each found again beside its own module); another file by its path relative to the nearest folder on the
Python path (or the working folder) holding it, by its absolute path outside them all or when two files read would
have one name. Two different SHA-256 under one name are refused when recorded, and a recorded file whose SHA-256 a worker reports changed stops the run
(:class:`~scenario_bank.read_files.ReadFilesError`).
A report of ``dv2s regress`` records, per failure kind it judged, the files that kind's plug-in read
(:func:`detector_reads`), which ``--baseline-report`` compares with the files here (:func:`changed_files`).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import re
import sys
import sysconfig
from importlib import metadata
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional

from policies.registry import (SB3_ALGORITHMS, SHIPPED_CHECKPOINT, parse_spec, registered_policies,
                               registered_policy_module)
from scenario_bank.atomic import atomic_write_json, file_sha256
from scenario_bank.failure_types import plugin_table
from scenario_bank.named_registry import replaced_built_ins
from scenario_bank.plugins import MAIN, code_modules
from scenario_bank.read_files import (ReadFile, ReadFilesError, changed_while_running, detector_label,
                                      labelled_module, plugin_label, python_path_folders, unwatched, user_reads,
                                      watch)
from scenario_bank.run_paths import resume_fix

__all__ = ["RESUME_FINGERPRINT", "resume_fingerprint", "fingerprint_changes", "check_policy_unchanged",
           "checkpoint_path", "installed_version", "MAX_HELPER_FILES", "CODE_IDENTITY", "dv2s_sources_sha256",
           "code_identity", "check_code_unchanged", "module_fingerprint", "detector_identity",
           "report_code_identity", "BUILT_IN", "read_facts", "run_read_facts", "with_recorded_reads",
           "DETECTOR_READS", "detector_reads", "changed_files", "ReadsRecorder"]


def _hash(path: Path) -> str:
    """The file's SHA-256, read without its being noted as a file the code read (it is dv2s's check)."""
    with unwatched():
        return file_sha256(path)


MAX_HELPER_FILES = 500
"""At most this many ``.py`` files beside a policy module are hashed (a policy in a huge folder)."""

_DV2S_ROOT = Path(__file__).resolve().parents[1]  # the folder holding dv2s's packages
_DV2S_PACKAGES = ("envs", "dv2s_gym", "policies", "scenario_bank")
_SKIPPED_DIRS = {"__pycache__", "site-packages", "dist-packages", "node_modules"}


def _outside_user_code() -> List[Path]:
    roots = {sysconfig.get_paths()[key] for key in ("stdlib", "platstdlib", "purelib", "platlib", "scripts")}
    return [Path(r).resolve() for r in roots if r] + [_DV2S_ROOT / p for p in _DV2S_PACKAGES]


def _is_under(path: Path, roots: Iterable[Path]) -> bool:
    return any(path == root or root in path.parents for root in roots)


def _helper_files(module_file: Path, module: str) -> List[Path]:
    """The user's ``.py`` files a ``module:attribute`` policy may use (see the module docstring)."""
    folder = module_file.resolve().parent
    for _ in range(module.count(".")):  # a package's tree starts at its top-level folder
        folder = folder.parent
    excluded = _outside_user_code()
    found = set()
    if module.count("."):
        candidates = (p for p in folder.rglob("*.py") if not (_SKIPPED_DIRS & set(p.parts)))
    else:
        candidates = folder.glob("*.py")
    for path in candidates:
        if len(found) >= MAX_HELPER_FILES:
            break
        found.add(path.resolve())
    found.update(_loaded_user_files())
    return sorted(p for p in found if p.is_file() and not _is_under(p, excluded))


def _loaded_user_files() -> List[Path]:
    """The ``.py`` file of every module loaded in this process that is the user's code, wherever it lives (module
    docstring)."""
    excluded = _outside_user_code()
    found = set()
    for loaded in list(sys.modules.values()):
        name = getattr(loaded, "__file__", None)
        if not name or not str(name).endswith(".py"):
            continue
        path = Path(name).resolve()
        if not (_SKIPPED_DIRS & set(path.parts)) and not _is_under(path, excluded) and path.is_file():
            found.add(path)
    return sorted(found)


def _module_file(name: str) -> Optional[Path]:
    if name == MAIN:  # a script's registrations: its file (none for python -c or an interactive session)
        main_file = getattr(sys.modules.get("__main__"), "__file__", None)
        return Path(main_file) if main_file and Path(main_file).is_file() else None
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    origin = getattr(spec, "origin", None) if spec is not None else None
    if origin and Path(origin).is_file():
        return Path(origin)
    here = Path.cwd() / Path(*name.split("."))  # load_policy finds a module:attribute policy in this folder too
    for path in (here.with_suffix(".py"), here / "__init__.py"):
        if path.is_file():
            return path
    return None


def installed_version() -> str:
    """The installed dv2s-gym distribution's version (``"unknown"`` when run from a source tree without one)."""
    try:
        return metadata.version("dv2s-gym")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "unknown"


def checkpoint_path(base: str) -> Optional[Path]:
    """The checkpoint file a policy spec's base names (``dv2s-ppo``, ``model.zip``, ``ppo:PATH``, a folder holding
    ``model.zip``), ``None`` for a driver or a ``module:attribute`` policy."""
    if base == "dv2s-ppo":
        return SHIPPED_CHECKPOINT
    prefix, sep, rest = base.partition(":")
    if sep and prefix.lower() in SB3_ALGORITHMS:
        base = rest
    path = Path(base)
    if path.is_dir():
        path = path / "model.zip"
    return path if path.suffix == ".zip" or (sep and prefix.lower() in SB3_ALGORITHMS) else None


RESUME_FINGERPRINT = "policy_fingerprint"
"""The key under which a resumable run's settings record :func:`resume_fingerprint` of its policy."""


def resume_fingerprint(spec: str) -> Dict[str, Any]:
    """What a resumed run must find unchanged in its policy, ``{description: value}`` (every key names what it is):
    the spec's options, the dv2s version, the bytes of every option value naming a file, and the checkpoint's bytes
    (with its model card's), a registered driver's module or a ``module:attribute`` policy's source and its helper
    files (module docstring)."""
    base, options = parse_spec(spec)
    facts: Dict[str, Any] = {"options": json.dumps(options, sort_keys=True, default=str),
                             "dv2s version": installed_version()}
    for key, value in sorted(options.items()):
        if isinstance(value, str) and value and Path(value).is_file():
            facts[f"option {key} file {value} (SHA-256)"] = _hash(Path(value))
    checkpoint = checkpoint_path(base)
    if checkpoint is not None:
        resolved = checkpoint.resolve()
        facts[f"checkpoint {checkpoint} (SHA-256)"] = _hash(resolved) if resolved.is_file() else "missing"
        card = resolved.parent / "model_card.json"
        if card.is_file():
            facts[f"model card {card} (SHA-256)"] = _hash(card)
    elif base in registered_policies():
        module = registered_policy_module(base)
        found = _module_file(module) if module else None
        if found is not None:
            facts[f"module {module} source (SHA-256)"] = _hash(found)
    elif ":" in base:
        facts.update(module_fingerprint(base.partition(":")[0]))
    return facts


def module_fingerprint(module: str) -> Dict[str, str]:
    """The SHA-256 of a user's module's source file and of its helper files (module docstring), ``{description:
    SHA-256}`` (``"not found"`` for a module with no source file)."""
    found = _module_file(module)
    facts = {f"module {module} source (SHA-256)": _hash(found) if found else "not found"}
    if found is not None:
        for helper in _helper_files(found, module):
            if helper != found.resolve():
                facts[f"module file {_file_label(helper, module, 'beside')} (SHA-256)"] = _hash(helper)
    return facts


def _search_folders() -> List[Path]:
    """Where a user's file recorded by a relative path is looked for: the Python path's folders (not Python's own),
    then the working folder."""
    return python_path_folders() + [Path.cwd().resolve()]


def _file_label(path: Path, anchor: Optional[str] = None, word: str = "read by") -> str:
    """How a user's file is named in an identity (module docstring). With an ``anchor`` module (the plug-in that read
    it, the module a helper file is beside) found by its name on the Python path, and the file in the same Python
    path folder: ``"<path relative to the module's folder> <word> <module>"``, so that two plug-ins' ``limits.json``
    are two names. Else relative to the nearest :func:`_search_folders` folder holding it, else its absolute path.
    Either way the name stays when the folder holding the plug-ins moves, with the Python path."""
    path = Path(path).resolve()
    holding = [folder for folder in _search_folders() if folder in path.parents]
    if not holding:
        return str(path)
    nearest = max(holding, key=lambda folder: len(folder.parts))
    module = _module_by_name(anchor) if anchor and anchor != MAIN else None
    if module is not None and nearest in module.parents:
        return f"{Path(os.path.relpath(path, module.parent)).as_posix()} {word} {anchor}"
    return path.relative_to(nearest).as_posix()


def _module_by_name(name: str) -> Optional[Path]:
    """The source file module ``name`` has on the Python path (or in the working folder), found without importing
    anything."""
    parts = name.split(".")
    for folder in _search_folders():
        base = folder.joinpath(*parts)
        for path in (base.with_suffix(".py"), base / "__init__.py"):
            if path.is_file():
                return path.resolve()
    return None


def _found_file(key: str) -> Optional[Path]:
    """The file a user-file fact (:data:`_USER_FILE`) names, as it is found here now (``None``: not found)."""
    match = _USER_FILE.match(key)
    if match is None:
        return None
    label = match["path"]
    if match["kind"] == "user module":
        return _module_by_name(label)
    anchored = _ANCHORED.match(label)
    if anchored is not None:  # relative to the folder of the module that read it (or that it is beside)
        module = _module_by_name(anchored["anchor"])
        found = (module.parent / anchored["path"]).resolve() if module is not None else None
        return found if found is not None and found.is_file() else None
    if Path(label).is_absolute():
        return Path(label) if Path(label).is_file() else None
    return next((folder / label for folder in _search_folders() if (folder / label).is_file()), None)


_ANCHORED = re.compile(r"^(?P<path>.+) (?:read by|beside) (?P<anchor>[A-Za-z_][\w.]*)$")
"""A user file's name relative to a module's folder (:func:`_file_label`)."""

_MODULE_SOURCE = re.compile(r"^module (?P<name>\S+) source \(SHA-256\)$")


def _covered_file(key: str) -> Optional[Path]:
    """The file a fact of an identity names (a user file, or a plug-in module's source), ``None`` for another fact."""
    match = _MODULE_SOURCE.match(key)
    if match is not None:
        found = _module_file(match["name"])
        return found.resolve() if found is not None else None
    found = _found_file(key)
    return found.resolve() if found is not None else None


def _read_key(read: ReadFile, detectors: Mapping[str, str]) -> str:
    """The fact naming a file a run read: ``user module <name>`` for a module found by its name, else ``user file
    <path>`` (:func:`_file_label`, relative to the folder of the plug-in module that read it when one did:
    ``detectors``, failure kind -> module, names a detector's)."""
    if read.module and read.module != MAIN and _module_by_name(read.module) == Path(read.path):
        return f"user module {read.module} (SHA-256)"
    readers = {labelled_module(label, dict(detectors)) for label in read.labels} - {None, MAIN}
    return f"user file {_file_label(Path(read.path), min(readers) if readers else None)} (SHA-256)"


def _add_fact(facts: Dict[str, Any], key: str, value: Any, path: Any = None) -> None:
    """``facts[key] = value``, refusing a second, different value under one name (two files named alike)."""
    if key in facts and facts[key] != value:
        raise ReadFilesError(
            f"two different files the code read would be recorded as {key!r} (SHA-256 {str(facts[key])[:12]} and "
            f"{str(value)[:12]}{f', the second {path}' if path else ''}), so a resume could check only one; give "
            "them distinct names or folders on the Python path")
    facts[key] = value


def read_facts(reads: Iterable[ReadFile], covered: Iterable[str] = ()) -> Dict[str, str]:
    """``{fact: SHA-256}`` of the user's files a run read (:func:`scenario_bank.read_files.user_reads`), each named
    so that moving the folder holding it (with the Python path) keeps its name: a module by its name
    (``user module myplugins.helper``), a data file a plug-in read by its path relative to that plug-in module's
    folder (``user file limits.json read by myfail``), another by its path relative to the Python path's folder
    holding it (``user file limits.json``), else by its absolute path. A file the facts ``covered`` already name is
    left out.

    Raises:
        ReadFilesError: two files with different bytes would have one name.
    """
    seen = {path for path in (_covered_file(key) for key in covered) if path is not None}
    detectors = plugin_table()["detectors"]
    keyed = [(read, _read_key(read, detectors)) for read in sorted(reads, key=lambda r: r.path)
             if Path(read.path) not in seen]
    paths: Dict[str, set] = {}
    for read, key in keyed:
        paths.setdefault(key, set()).add(read.path)
    facts: Dict[str, str] = {}
    for read, key in keyed:
        if len(paths[key]) > 1:  # two files one relative name would give (read outside any plug-in): their paths
            key = f"user file {Path(read.path).resolve()} (SHA-256)"
        _add_fact(facts, key, read.sha256, read.path)
    return facts


def with_recorded_reads(recorded: Mapping[str, Any], now: Mapping[str, Any]) -> Dict[str, Any]:
    """``now`` (an identity about to be recorded again) with the user files ``recorded`` holds and ``now`` does not
    (files read by the workers of an earlier part of the run; checked unchanged by :func:`check_code_unchanged`)."""
    merged = dict(now)
    for key, value in recorded.items():
        if _USER_FILE.match(key) and key not in merged:
            merged[key] = value
    return merged


def fingerprint_changes(recorded: Dict[str, Any], now: Dict[str, Any]) -> List[str]:
    """``"<fact>: run has <old>, now <new>"`` for every fact of two fingerprints that differs (sorted)."""
    def show(value: Any) -> str:
        text = "absent" if value is None else str(value)
        return text[:12] if len(text) == 64 else text
    keys = sorted(set(recorded) | set(now))
    return [f"{key}: run has {show(recorded.get(key))}, now {show(now.get(key))}" for key in keys
            if recorded.get(key) != now.get(key)]


_USER_FILE = re.compile(r"^(?P<kind>module file|user file|user module) (?P<path>.+) \(SHA-256\)$")
"""A fact naming one of the user's files (:func:`module_fingerprint`, :func:`read_facts`), compared as the run
recorded it."""


def _as_recorded(recorded: Mapping[str, Any], now: Mapping[str, Any]) -> Dict[str, Any]:
    """``now`` with the user's files (:data:`_USER_FILE`) as the run ``recorded`` them: each recorded file hashed as
    it is now (``"missing"`` when gone), a file the run did not record left out (module docstring)."""
    facts = {key: value for key, value in now.items() if key in recorded or not _USER_FILE.match(key)}
    for key in recorded:
        if _USER_FILE.match(key) and key not in now:
            path = _found_file(key)
            facts[key] = _hash(path) if path is not None else "missing"
    return facts


def check_policy_unchanged(recorded: Mapping[str, Any], spec: str, *, folder: Any, run: str,
                           error: type, key: str = RESUME_FINGERPRINT, role: str = "policy") -> Dict[str, Any]:
    """The policy's :func:`resume_fingerprint`, after checking it against the one ``recorded`` under
    :data:`RESUME_FINGERPRINT` (or ``key``: another policy of the run, its ``role``, such as the mining run's
    ``"reference driver"``) in the settings of the ``run``, e.g. ``"mining run"``, in ``folder`` (a record of the
    run's format, :func:`~scenario_bank.run_identity.check_format`, holds one).

    Raises:
        error: ``"<folder> holds a <run> of <spec> whose policy has changed since (<fact>: run has ..., now ...);
            restore the policy ..., or pass a new --out"`` when a fact differs.
    """
    now = resume_fingerprint(spec)
    old = dict(recorded.get(key) or {})
    changes = fingerprint_changes(old, _as_recorded(old, now))
    if changes and role != "policy":
        raise error(f"{folder} holds a {run} whose {role} {spec} has changed since ({'; '.join(changes[:3])}"
                    f"{f'; and {len(changes) - 3} more' if len(changes) > 3 else ''}); " + resume_fix(
                        folder, f"restore the {role} (its checkpoint or module as the run used it), or pass a new "
                                "--out"))
    if changes:
        raise error(f"{folder} holds a {run} of {spec} whose policy has changed since ({'; '.join(changes[:3])}"
                    f"{f'; and {len(changes) - 3} more' if len(changes) > 3 else ''}); " + resume_fix(
                        folder, "restore the policy (its checkpoint or module as the run used it), or pass a new "
                                "--out"))
    return now


# --------------------------------------------------------------------------- the code a run runs
CODE_IDENTITY = "code_identity"
"""The key under which a resumable run's record holds :func:`code_identity`."""

_CODE_GROUPS = (("dv2s sources", "dv2s sources"), ("plug-in modules", "plug-in modules"),
                ("module ", "plug-in modules' source"), ("user ", "files the code read"), ("failure types", "failure types"),
                ("detectors", "detectors"), ("replaced built-ins", "replaced built-ins"))
"""How a difference is named in a refusal: the first group whose prefix a fact's key starts with."""


_SOURCE_SUFFIXES = (".py", ".scenic", ".xodr", ".json")
"""What of dv2s's packages decides how a run goes: its code, the Scenic world models, the OpenDRIVE maps and the
records of the shipped bank and the loop's untouched set."""
_NOT_SOURCES = ("dv2s_gym/evalset", "policies/checkpoints")
"""Data no run reads (the evaluation set) or that a run fingerprints apart (a policy's checkpoint)."""


def dv2s_sources_sha256() -> str:
    """One SHA-256 over dv2s's four packages (``envs``, ``dv2s_gym``, ``policies``, ``scenario_bank``): the paths
    and contents of every ``.py``, ``.scenic``, ``.xodr`` and ``.json`` file in them, but the evaluation set and the
    shipped checkpoint."""
    digest = hashlib.sha256()
    skipped = [_DV2S_ROOT / folder for folder in _NOT_SOURCES]
    for package in _DV2S_PACKAGES:
        root = _DV2S_ROOT / package
        for path in sorted(root.rglob("*")) if root.is_dir() else []:
            if path.suffix not in _SOURCE_SUFFIXES or "__pycache__" in path.parts or not path.is_file():
                continue
            if any(folder in path.parents for folder in skipped):
                continue
            digest.update(str(path.relative_to(_DV2S_ROOT)).encode() + b"\0" + _hash(path).encode() + b"\n")
    return digest.hexdigest()


def code_identity(exclude: Iterable[Any] = (), reads: Iterable[ReadFile] = ()) -> Dict[str, Any]:
    """What a resumed run must find unchanged in the code it runs, ``{description: value}`` (module docstring):
    ``"dv2s sources (SHA-256)"``, ``"plug-in modules"`` (:func:`~scenario_bank.plugins.code_modules`) with each
    one's :func:`module_fingerprint`, ``"failure types"`` and ``"detectors"`` registered by plug-ins (name -> module),
    ``"replaced built-ins"`` (:func:`scenario_bank.named_registry.replaced_built_ins`) and the user's files read so
    far (:func:`read_facts`) by this process and by the workers (``reads``), but those under a folder of
    ``exclude`` (the run's own folder, its bank). Starts watching what this process reads
    (:func:`scenario_bank.read_files.watch`)."""
    watch()
    modules = code_modules()
    facts: Dict[str, Any] = {"dv2s sources (SHA-256)": dv2s_sources_sha256(), "plug-in modules": modules}
    for module in modules:
        for key, value in module_fingerprint(module).items():
            _add_fact(facts, key, value)
    facts.update(plugin_table())
    facts["replaced built-ins"] = replaced_built_ins()
    for key, value in run_read_facts(exclude, reads, covered=facts).items():
        _add_fact(facts, key, value)
    return facts


def run_read_facts(exclude: Iterable[Any] = (), reads: Iterable[ReadFile] = (),
                   covered: Iterable[str] = ()) -> Dict[str, str]:
    """:func:`read_facts` of the files this process read and of ``reads`` (a pool's, read by its workers), but those
    under a folder of ``exclude``."""
    excluded = [Path(folder).resolve() for folder in exclude if folder]
    found = dict(user_reads(excluded))
    for read in reads:
        if not any(folder == Path(read.path) or folder in Path(read.path).parents for folder in excluded):
            found.setdefault(read.path, read)
    return read_facts(found.values(), covered=[key for key in covered if _USER_FILE.match(key)
                                               or _MODULE_SOURCE.match(key)])


class ReadsRecorder:
    """Adds the user's files a pool's workers read (``pool.files_read``, :mod:`dv2s_gym.workers.pool`) to the code
    identity a run recorded in the JSON file ``record`` (under :data:`CODE_IDENTITY`, inside the objects ``where``
    names), as new ones appear, so that a resume checks them too; files under a folder of ``exclude`` are left out.
    A recorded file whose SHA-256 is another now (it changed while the run ran) raises
    :class:`~scenario_bank.read_files.ReadFilesError`."""

    def __init__(self, record: Path, pool: Any, exclude: Iterable[Any] = (), where: Iterable[str] = ()) -> None:
        self.record_file, self.pool, self.exclude, self.where = Path(record), pool, list(exclude), list(where)
        self.count = -1

    def record(self) -> None:
        """Record the files read since the last call (at once when there are none: the common case)."""
        reads = getattr(self.pool, "files_read", None) or {}
        if len(reads) == self.count:
            return
        self.count = len(reads)
        values = json.loads(self.record_file.read_text())
        holder = values
        for key in self.where:
            holder = holder[key]
        identity = dict(holder.get(CODE_IDENTITY) or {})
        facts = run_read_facts(self.exclude, reads.values(), covered=identity)
        for key, value in facts.items():
            if key in identity and identity[key] != value and _USER_FILE.match(key):
                found = _found_file(key)
                raise changed_while_running(str(found) if found is not None else key, str(identity[key]), value)
        new = {key: value for key, value in facts.items() if key not in identity}
        if new:
            holder[CODE_IDENTITY] = {**identity, **new}
            atomic_write_json(self.record_file, values)


def _code_group(key: str) -> str:
    return next((name for prefix, name in _CODE_GROUPS if key.startswith(prefix)), key)


def check_code_unchanged(recorded: Mapping[str, Any], *, run: str, error: type,
                         now: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """The :func:`code_identity` of this process (or ``now``), after checking it against the one ``recorded``
    under :data:`CODE_IDENTITY` (the record of ``run``, e.g. ``"out/mine holds a mining run"``).

    Raises:
        error: ``"<run> made with other code (<what>: run has ..., now ...); restore the code the run used, or
            start a new --out folder"``, ``<what>`` naming each part that differs (``dv2s sources``, ``plug-in
            modules``, ``plug-in modules' source``, ``failure types``, ``detectors``, ``replaced built-ins``).
    """
    current = dict(code_identity() if now is None else now)
    old = dict(recorded.get(CODE_IDENTITY) or {})
    changes = fingerprint_changes(old, _as_recorded(old, current))
    if changes:
        parts = sorted({_code_group(change.partition(":")[0]) for change in changes},
                       key=lambda name: [g for _, g in _CODE_GROUPS].index(name) if name in
                       [g for _, g in _CODE_GROUPS] else len(_CODE_GROUPS))
        shown = "; ".join(changes[:3]) + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
        raise error(f"{run} made with other code ({', '.join(parts)} differ: {shown}); restore the code the run "
                    "used (dv2s's sources, the plug-in modules DV2S_PLUGINS names, the files they read), or start a "
                    "new --out folder")
    return current


# --------------------------------------------------------------------------- who judges a failure kind
BUILT_IN = "dv2s-gym's own"
"""How :func:`detector_identity` names the product's own failure type or detector."""


def _source_sha256(module: str) -> str:
    found = _module_file(module)
    return _hash(found) if found is not None else "not found"


def detector_identity(kinds: Iterable[str]) -> Dict[str, Dict[str, Any]]:
    """Who decides each failure kind of ``kinds`` in this process (the detector part of :func:`code_identity`):
    ``{kind: {"failure type": module, "detector": module, "sources (SHA-256)": {module: SHA-256 of its source}}}``,
    a module being the plug-in module that registered the type or its detector, or :data:`BUILT_IN`."""
    table = plugin_table()
    found: Dict[str, Dict[str, Any]] = {}
    for kind in kinds:
        modules = {"failure type": table["failure types"].get(kind) or BUILT_IN,
                   "detector": table["detectors"].get(kind) or BUILT_IN}
        found[kind] = {**modules, "sources (SHA-256)": {module: _source_sha256(module) for module in
                                                         sorted(set(modules.values()) - {BUILT_IN})}}
    return found


def report_code_identity(kinds: Iterable[str], reads: Iterable[ReadFile] = ()) -> Dict[str, Any]:
    """The code a report's episodes were judged by, for a report to record: ``"dv2s sources (SHA-256)"``, the
    ``"plug-in modules"`` loaded (module -> SHA-256 of its source), the ``"detectors"`` of the failure ``kinds``
    judged (:func:`detector_identity`), the ``"replaced built-ins"`` and the :data:`DETECTOR_READS`: the user's
    files each kind's plug-in read while it was imported or detected (in this process or, ``reads``, a worker)."""
    kinds = list(kinds)
    return {"dv2s sources (SHA-256)": dv2s_sources_sha256(),
            "plug-in modules": {module: _source_sha256(module) for module in code_modules()},
            "detectors": detector_identity(kinds), "replaced built-ins": replaced_built_ins(),
            DETECTOR_READS: detector_reads(kinds, reads)}


DETECTOR_READS = "files read by detectors"
"""The key of a report's code identity holding, per failure kind judged, the user's files (:func:`read_facts`,
``{fact: SHA-256}``) its plug-in read while imported or while detecting."""


def detector_reads(kinds: Iterable[str], reads: Iterable[ReadFile] = ()) -> Dict[str, Dict[str, str]]:
    """Per failure kind of ``kinds`` that a plug-in decides, the user's files read under its detector's label or
    while its plug-in module (the failure type's or the detector's) was imported: in this process or ``reads``."""
    watch()
    found = dict(user_reads())
    for read in reads:
        known = found.get(read.path)
        labels = set(read.labels) | set(known.labels if known is not None else ())
        found[read.path] = ReadFile(read.path, read.module, read.sha256, tuple(sorted(labels)))
    table = plugin_table()
    facts: Dict[str, Dict[str, str]] = {}
    for kind in kinds:
        modules = {table["failure types"].get(kind), table["detectors"].get(kind)} - {None}
        labels = {detector_label(kind)} | {plugin_label(module) for module in modules}
        facts[kind] = read_facts(read for read in found.values() if labels & set(read.labels))
    return facts


def changed_files(facts: Mapping[str, str]) -> List[str]:
    """``"<fact>: recorded <old>, now <new>"`` for every user file of ``facts`` (:func:`read_facts`) whose bytes
    here differ from the recorded SHA-256 (``missing`` when it is not found)."""
    changed = []
    for key, recorded in sorted(facts.items()):
        path = _found_file(key)
        now = _hash(path) if path is not None else "missing"
        if now != recorded:
            changed.append(f"{key}: recorded {str(recorded)[:12]}, now {now[:12]}")
    return changed
