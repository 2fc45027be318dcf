"""The bank's check of untrusted Scenic: bounded checks here, then everything else in the jail.

The user's process only checks what is linear and bounded (type, size, encoding:
:func:`bounded_precheck`); the allowlist (:mod:`scenario_bank.safety`), Scenic's
parser and compiler, sampling and a few simulated seconds of the episode run in
a fresh jailed worker (:mod:`scenario_bank.jail`: bubblewrap namespaces, seccomp,
CPU, memory, file-size and wall-clock limits, an empty environment, no network,
no view of the user's files). A scene that never satisfies its requirements ends
as "no scene sampled in N iterations".

Every way it can fail is an :class:`~scenario_bank.safety.UnsafeScenarioError`
(the allowlist refused it) or a :class:`SandboxError` that names the stage and
the limit ("exceeded the 30 s CPU-time limit while running"). Successful checks
are cached by script hash, dv2s-gym code version and limits under the user cache
directory, so the same script is not re-run."""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence
import resource
from importlib.metadata import version

import numpy as np

from scenario_bank.atomic import atomic_write_text
from scenario_bank.cache import cache_dir as user_cache_dir
from scenario_bank.jail import JailedProcess, JailError, JailLimitError, JailLimits
from scenario_bank.jail.process import JailRemoteError
from scenario_bank.precheck import precheck_text
from scenario_bank.safety import SafetyFinding, UnsafeScenarioError
from scenario_bank.simulator_worker import SCRATCH, simulator_worker
from scenario_bank.errors import DV2SError
from scenario_bank.errors import SettingError, WrongTypeError

__all__ = ["SandboxLimits", "SandboxResult", "SandboxError", "run_in_sandbox", "verify_script", "check_in_jail",
           "bounded_precheck", "cache_dir"]

CODE_ROOT = Path(__file__).resolve().parents[1]
"""The folder holding ``scenario_bank`` and the simulator's package: the child imports this code, not an installed
copy."""
_GIB = 2**30


@dataclass(frozen=True)
class SandboxLimits:
    """Resource limits of one sandboxed check.

    A normal bank scenario needs about 2.1 s of CPU, 0.72 GiB of peak address
    space and 2.1 s of wall time for import, compile, two samples and a 3-s run
    (measured on the shipped bank); the defaults leave about 14x, 4x and 28x
    headroom for larger maps and loaded machines. Environment variables
    ``DV2S_SANDBOX_CPU`` (s), ``DV2S_SANDBOX_MEMORY_MB`` and ``DV2S_SANDBOX_WALL``
    (s) override them (:meth:`from_env`).
    """

    cpu_seconds: int = 30
    memory_bytes: int = 3 * _GIB
    wall_seconds: float = 60.0
    file_bytes: int = 256 * 2**20

    @classmethod
    def from_env(cls) -> "SandboxLimits":
        """The defaults, overridden by ``DV2S_SANDBOX_CPU``/``_MEMORY_MB``/``_WALL`` when set."""
        base = cls()
        try:
            return cls(
                cpu_seconds=int(os.environ.get("DV2S_SANDBOX_CPU", base.cpu_seconds)),
                memory_bytes=int(float(os.environ.get("DV2S_SANDBOX_MEMORY_MB", base.memory_bytes / 2**20)) * 2**20),
                wall_seconds=float(os.environ.get("DV2S_SANDBOX_WALL", base.wall_seconds)),
            )
        except ValueError as error:
            raise SettingError(f"bad DV2S_SANDBOX_* limit: {error}; give whole seconds and megabytes") from None

    def describe_memory(self) -> str:
        value = self.memory_bytes / _GIB
        return f"{value:g} GiB" if value >= 1 else f"{self.memory_bytes / 2**20:g} MiB"


@dataclass
class SandboxResult:
    """Outcome of one sandboxed check; ``ok`` or a ``stage``/``limit``/``message`` saying why not."""

    ok: bool
    stage: str
    message: str = ""
    limit: Optional[str] = None
    error_type: Optional[str] = None
    wall_seconds: float = 0.0
    timings: Dict[str, float] = field(default_factory=dict)
    cached: bool = False

    def as_dict(self) -> Dict[str, Any]:
        return asdict(self)


class SandboxError(DV2SError, ValueError):
    """A script failed its sandboxed check; ``result`` says at which stage and by which limit."""

    def __init__(self, message: str, result: SandboxResult) -> None:
        super().__init__(message)
        self.result = result

    @property
    def stage(self) -> str:
        return self.result.stage

    @property
    def limit(self) -> Optional[str]:
        return self.result.limit


def run_in_sandbox(
    script: str,
    *,
    name: str = "<sandboxed>",
    limits: Optional[SandboxLimits] = None,
    seeds: Sequence[int] = (0, 1),
    run_seconds: float = 3.0,
    max_sample_iterations: int = 2000,
    files: Optional[Dict[str, bytes]] = None,
) -> SandboxResult:
    """Check, compile, sample (each seed) and run ``script`` for ``run_seconds`` in a fresh jailed worker.

    ``files`` are the files beside the script it may need (``localPath`` maps), by
    relative name. Never raises for a failure of the script: the result says what
    happened. Raises :class:`~scenario_bank.jail.JailUnavailableError` when the
    jail cannot be created here, :class:`~scenario_bank.simulator_worker.NoSimulatorError` when no simulator
    layer is loaded (:mod:`scenario_bank.simulator_worker`).
    """
    worker_module = simulator_worker()
    limits = limits or SandboxLimits.from_env()
    jail_limits = JailLimits.from_env(cpu_seconds=limits.cpu_seconds, memory_bytes=limits.memory_bytes,
                                      file_bytes=limits.file_bytes, request_seconds=limits.wall_seconds,
                                      start_seconds=max(limits.wall_seconds, 120.0))
    start = time.perf_counter()
    cpu_before = _children_cpu()
    payload = {name_: np.frombuffer(data, dtype=np.uint8) for name_, data in (files or {}).items()}
    stage = "import"
    try:
        with JailedProcess(worker_module, limits=jail_limits, name=name) as worker:
            stage = "compile"
            data = worker.call("verify", script=script, name=name, seeds=[int(s) for s in seeds],
                               run_seconds=float(run_seconds), max_sample_iterations=int(max_sample_iterations),
                               files=payload)
    except JailLimitError as error:
        where = _WHERE.get(error.stage or stage, "while checking")
        what = {"wall": f"exceeded the {limits.wall_seconds:g} s wall-clock limit",
                "cpu": f"exceeded the {limits.cpu_seconds} s CPU-time limit",
                "memory": f"exceeded the {limits.describe_memory()} memory limit",
                "file": f"wrote a file over the {limits.file_bytes}-byte limit"}.get(error.limit, f"hit the {error.limit} limit")
        return SandboxResult(False, stage, _with_output(f"{what} {where}", error.output), error.limit,
                             "MemoryError" if error.limit == "memory" else None, time.perf_counter() - start)
    except JailRemoteError as error:
        failed = str(error.details.get("stage") or stage)
        if error.error_type == "UnsafeScenarioError":
            findings = _findings(error.details.get("findings"))
            raise UnsafeScenarioError(findings or [SafetyFinding(0, "script", error.plain_message)], name) from None
        limit = error.details.get("limit")
        if error.error_type == "RecursionError" or "RecursionError" in error.plain_message:
            message, limit = f"exceeded Python's recursion limit {_WHERE.get(failed, '')}: {error.plain_message}", "recursion"
        else:
            message = f"{error.error_type} {_WHERE.get(failed, '')}: {error.plain_message}"
        return SandboxResult(False, failed, _with_output(message, error.output), limit, error.error_type,
                             time.perf_counter() - start)
    except JailError as error:
        return SandboxResult(False, stage, f"the sandboxed check died {_WHERE.get(stage, '')}: {error}", None, None,
                             time.perf_counter() - start)
    wall = time.perf_counter() - start
    if not isinstance(data, dict):
        return SandboxResult(False, stage, "the sandboxed check answered nothing", None, None, wall)
    timings = data.get("timings") if isinstance(data.get("timings"), dict) else {}
    timings = {str(k): float(v) for k, v in timings.items() if isinstance(v, (int, float))}
    # a worker bubblewrap started is our child; one the zygote forked reports its own CPU time
    timings["cpu"] = max(timings.get("cpu", 0.0), _children_cpu() - cpu_before)
    if data.get("ok") is True:
        return SandboxResult(True, "done", "", None, None, wall, timings)
    return SandboxResult(False, str(data.get("stage", "sample")), str(data.get("message", ""))[:4000],
                         data.get("limit") if isinstance(data.get("limit"), str) else None,
                         str(data.get("error_type", "")) or None, wall, timings)


def _findings(data: Any) -> List[SafetyFinding]:
    findings = []
    for item in data if isinstance(data, list) else []:
        if isinstance(item, dict):
            findings.append(SafetyFinding(int(item.get("line") or 0) if isinstance(item.get("line"), int) else 0,
                                          str(item.get("construct", ""))[:200], str(item.get("reason", ""))[:500]))
    return findings


def bounded_precheck(script: Any, name: str = "<script>") -> None:
    """The checks the user's process runs on untrusted text before the jail sees it
    (:func:`scenario_bank.precheck.precheck_text`: type, size, encoding, nesting; linear and bounded).

    Everything that parses the text runs in the jail.
    """
    if not isinstance(script, str):
        raise WrongTypeError(f"{name}: a Scenic script is text (str), not {type(script).__name__}")
    precheck_text(script, name)


def check_in_jail(script: str, *, name: str = "<script>", absolute_maps: bool = False) -> List[SafetyFinding]:
    """The allowlist's findings for ``script``, computed in a fresh jailed worker (empty list: it passed)."""
    bounded_precheck(script, name)
    with JailedProcess(simulator_worker(), name=name) as worker:
        return _findings(worker.call("check", script=script, absolute_maps=absolute_maps))


_WHERE = {"import": "while starting", "start": "while starting", "compile": "while compiling",
          "sample": "while sampling a scene", "run": "while running the episode", "verify": "while compiling"}


def _with_output(message: str, output: str) -> str:
    if not output:
        return message
    return f"{message}; the script printed (last {len(output)} characters): {output[-2000:]}"


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


# ---------------------------------------------------------------- verification with a cache
def cache_dir() -> Path:
    """Where verified-script records live: ``sandbox/`` in :func:`scenario_bank.cache.cache_dir`."""
    return user_cache_dir() / "sandbox"


_CODE_VERSION: Optional[str] = None


def code_version() -> str:
    """A digest of the code a sandboxed check runs (the simulator's package, the safety check, the sandbox,
    Scenic's version)."""
    global _CODE_VERSION
    if _CODE_VERSION is None:
        digest = hashlib.sha256()
        simulator = CODE_ROOT / simulator_worker().partition(".")[0]
        files = sorted([*simulator.rglob("*.py"), *simulator.rglob("*.scenic"),
                        *(CODE_ROOT / "scenario_bank").rglob("*.py"), *(CODE_ROOT / "scenario_bank" / "maps").glob("*.xodr")])
        for path in files:
            digest.update(str(path.relative_to(CODE_ROOT)).encode())
            digest.update(path.read_bytes())
        try:
            digest.update(f"scenic {version('scenic')} highway-env {version('highway-env')}".encode())
        except Exception:  # metadata missing: the file digest alone still tracks our code
            pass
        _CODE_VERSION = digest.hexdigest()
    return _CODE_VERSION


def _cache_key(script: str, limits: SandboxLimits, request: Dict[str, Any]) -> str:
    payload = json.dumps([hashlib.sha256(script.encode("utf-8")).hexdigest(), code_version(), asdict(limits), request],
                         sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


def _outside_names(message: str, name: str) -> str:
    """``message`` with the jail's copy of the script named as the caller named it (``name``), and the files
    beside it by their names alone."""
    message = re.sub(re.escape(SCRATCH) + r"/\d+/[^/\s,:]+\.scenic", lambda _: name, message)
    return re.sub(re.escape(SCRATCH) + r"/\d+/", "", message)


def verify_script(
    script: str,
    *,
    name: str = "<script>",
    limits: Optional[SandboxLimits] = None,
    seeds: Sequence[int] = (0, 1),
    run_seconds: float = 3.0,
    max_sample_iterations: int = 2000,
    use_cache: bool = True,
) -> SandboxResult:
    """Safety-check, then compile, sample and run ``script`` in the sandbox; raise if any of it fails.

    Raises :class:`~scenario_bank.safety.UnsafeScenarioError` (the allowlist refused it)
    or :class:`SandboxError` (it failed or hit a limit in the child). Passes are
    cached (``use_cache``); set ``DV2S_SANDBOX_CACHE=0`` to disable the cache.
    """
    bounded_precheck(script, name)
    limits = limits or SandboxLimits.from_env()
    request = {"seeds": list(seeds), "run_seconds": run_seconds, "max_sample_iterations": max_sample_iterations}
    use_cache = use_cache and os.environ.get("DV2S_SANDBOX_CACHE", "1") != "0"
    record = cache_dir() / f"{_cache_key(script, limits, request)}.json" if use_cache else None
    if record is not None and record.is_file():
        return SandboxResult(True, "done", "", cached=True)
    result = run_in_sandbox(script, name=name, limits=limits, seeds=seeds, run_seconds=run_seconds,
                            max_sample_iterations=max_sample_iterations)
    if not result.ok:
        raise SandboxError(f"{name} failed its sandboxed check: {_outside_names(result.message, name)}", result)
    if record is not None:
        try:
            record.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(record, json.dumps(result.as_dict()), fsync=False)
        except OSError:
            pass  # the cache is only an optimisation
    return result
