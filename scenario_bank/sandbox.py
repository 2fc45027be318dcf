"""The sandbox for untrusted Scenic: a safety check, then compile, sample and run in a limited child.

Defence in depth behind :mod:`scenario_bank.safety`: a script that passed the
allowlist is compiled, sampled and run for a few simulated seconds in a child
process (``python -m envs.sandbox_runner``, started by module name, so this
bottom layer imports nothing else of dv2s-gym) that has

* a CPU-time limit (``RLIMIT_CPU``) and an address-space limit (``RLIMIT_AS``),
  set before the interpreter starts, and a file-size limit;
* a wall-clock timeout, after which its whole process group is killed;
* a minimal environment: ``PATH``, a temporary ``HOME``/``TMPDIR`` and working
  directory, ``PYTHONPATH`` = the code root this module was loaded from, one
  BLAS/OpenMP thread, SDL offscreen; no API keys or other variables;
* a sampling budget: a scene that never satisfies its requirements ends as
  "no scene sampled in N iterations".

Every way it can fail is a :class:`SandboxError` that names the stage and the
limit ("exceeded the 30 s CPU-time limit while running"). Successful checks are
cached by script hash, dv2s-gym code version and limits under the user cache
directory, so the same script is not re-run.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

from scenario_bank.atomic import atomic_write_text
from scenario_bank.safety import UnsafeScenarioError, check_script

__all__ = ["SandboxLimits", "SandboxResult", "SandboxError", "run_in_sandbox", "verify_script", "cache_dir"]

CODE_ROOT = Path(__file__).resolve().parents[1]
"""The folder holding ``scenario_bank`` and ``envs``: the child imports this code, not an installed copy."""
RUNNER = "envs.sandbox_runner"
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
            raise ValueError(f"bad DV2S_SANDBOX_* limit: {error}; give whole seconds and megabytes") from None

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


class SandboxError(ValueError):
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


def _minimal_env(home: str) -> Dict[str, str]:
    return {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": home,
        "TMPDIR": home,
        "PYTHONPATH": str(CODE_ROOT),
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONHASHSEED": "0",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "SDL_VIDEODRIVER": "offscreen",
        "SDL_AUDIODRIVER": "dummy",
        "PYGAME_HIDE_SUPPORT_PROMPT": "1",
        "MPLBACKEND": "Agg",
        "LANG": "C.UTF-8",
    }


def _limit_child(limits: SandboxLimits):
    def apply() -> None:  # runs in the child between fork and exec
        import resource

        cpu = max(1, int(limits.cpu_seconds))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 2))  # SIGXCPU at the soft limit, SIGKILL 2 s later
        resource.setrlimit(resource.RLIMIT_AS, (limits.memory_bytes, limits.memory_bytes))
        resource.setrlimit(resource.RLIMIT_FSIZE, (limits.file_bytes, limits.file_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

    return apply


def _children_cpu() -> float:
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def run_in_sandbox(
    script: str,
    *,
    name: str = "<sandboxed>",
    limits: Optional[SandboxLimits] = None,
    seeds: Sequence[int] = (0, 1),
    run_seconds: float = 3.0,
    max_sample_iterations: int = 2000,
) -> SandboxResult:
    """Compile, sample (each seed) and run ``script`` for ``run_seconds`` in a limited child process.

    Does not run the safety check (:func:`verify_script` does, first); never
    raises for a failure of the script: the result says what happened.
    """
    limits = limits or SandboxLimits.from_env()
    request = {"script": script, "name": name, "seeds": list(seeds), "run_seconds": run_seconds,
               "max_sample_iterations": max_sample_iterations}
    start = time.perf_counter()
    cpu_before = _children_cpu()
    with tempfile.TemporaryDirectory(prefix="dv2s-sandbox-") as tmp:
        request_path, result_path = os.path.join(tmp, "request.json"), os.path.join(tmp, "result.json")
        with open(request_path, "w", encoding="utf-8") as handle:
            json.dump(request, handle)
        work = os.path.join(tmp, "work")
        os.mkdir(work)
        proc = subprocess.Popen(
            [sys.executable, "-s", "-m", RUNNER, request_path, result_path],
            cwd=work, env=_minimal_env(work), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, preexec_fn=_limit_child(limits), start_new_session=True, close_fds=True,
        )
        timed_out = False
        try:
            _, stderr = proc.communicate(timeout=limits.wall_seconds)
        except subprocess.TimeoutExpired:
            timed_out = True
            _kill_group(proc)
            _, stderr = proc.communicate()
        finally:
            _kill_group(proc)  # nothing the script started outlives the check
        wall = time.perf_counter() - start
        try:
            with open(result_path, encoding="utf-8") as handle:
                data = json.load(handle)
        except (OSError, ValueError):
            data = {}
    if isinstance(data.get("timings"), dict):
        data["timings"]["cpu"] = _children_cpu() - cpu_before
    return _interpret(data, proc.returncode, timed_out, stderr.decode("utf-8", "replace"), limits, wall)


def _interpret(data: Dict[str, Any], returncode: int, timed_out: bool, stderr: str, limits: SandboxLimits,
               wall: float) -> SandboxResult:
    stage = data.get("stage", "import")
    where = {"import": "while starting", "compile": "while compiling", "sample": "while sampling a scene",
             "run": "while running the episode"}.get(stage, f"at stage {stage}")
    timings = data.get("timings") or {}
    if timed_out:
        return SandboxResult(False, stage, f"exceeded the {limits.wall_seconds:g} s wall-clock limit {where}",
                             "wall", None, wall, timings)
    if returncode in (-signal.SIGXCPU, -signal.SIGKILL) and data.get("ok") is None:
        return SandboxResult(False, stage, f"exceeded the {limits.cpu_seconds} s CPU-time limit {where}",
                             "cpu", None, wall, timings)
    memory_words = ("MemoryError", "Cannot allocate memory", "Unable to allocate", "std::bad_alloc")
    if data.get("limit") == "memory" or (data.get("ok") is None and any(w in stderr for w in memory_words)):
        return SandboxResult(False, stage, f"exceeded the {limits.describe_memory()} memory limit {where}",
                             "memory", "MemoryError", wall, timings)
    if data.get("ok") is True:
        return SandboxResult(True, "done", "", None, None, wall, timings)
    if data.get("ok") is False:
        message = data.get("message", "")
        if data.get("limit") == "recursion":
            message = f"exceeded Python's recursion limit {where}: {message}"
        elif data.get("limit") != "iterations":
            message = f"{data.get('error_type', 'Error')} {where}: {message}"
        return SandboxResult(False, stage, message, data.get("limit"), data.get("error_type"), wall, timings)
    tail = " ".join(stderr.strip().splitlines()[-3:])[-400:]
    return SandboxResult(False, stage, f"the sandboxed check died {where} (exit status {returncode}): {tail}",
                         None, None, wall, timings)


# ---------------------------------------------------------------- verification with a cache
def cache_dir() -> Path:
    """Where verified-script records live: ``sandbox/`` in :func:`scenario_bank.cache.cache_dir`."""
    from scenario_bank.cache import cache_dir as root

    return root() / "sandbox"


_CODE_VERSION: Optional[str] = None


def code_version() -> str:
    """A digest of the code a sandboxed check runs (envs, the safety check, the sandbox, Scenic's version)."""
    global _CODE_VERSION
    if _CODE_VERSION is None:
        digest = hashlib.sha256()
        files = sorted([*(CODE_ROOT / "envs").rglob("*.py"), *(CODE_ROOT / "envs").rglob("*.scenic"),
                        *(CODE_ROOT / "scenario_bank").glob("*.py"), *(CODE_ROOT / "scenario_bank" / "maps").glob("*.xodr")])
        for path in files:
            digest.update(str(path.relative_to(CODE_ROOT)).encode())
            digest.update(path.read_bytes())
        try:
            from importlib.metadata import version

            digest.update(f"scenic {version('scenic')} highway-env {version('highway-env')}".encode())
        except Exception:  # metadata missing: the file digest alone still tracks our code
            pass
        _CODE_VERSION = digest.hexdigest()
    return _CODE_VERSION


def _cache_key(script: str, limits: SandboxLimits, request: Dict[str, Any]) -> str:
    payload = json.dumps([hashlib.sha256(script.encode("utf-8")).hexdigest(), code_version(), asdict(limits), request],
                         sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


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
    findings = check_script(script)
    if findings:
        raise UnsafeScenarioError(findings, name)
    limits = limits or SandboxLimits.from_env()
    request = {"seeds": list(seeds), "run_seconds": run_seconds, "max_sample_iterations": max_sample_iterations}
    use_cache = use_cache and os.environ.get("DV2S_SANDBOX_CACHE", "1") != "0"
    record = cache_dir() / f"{_cache_key(script, limits, request)}.json" if use_cache else None
    if record is not None and record.is_file():
        return SandboxResult(True, "done", "", cached=True)
    result = run_in_sandbox(script, name=name, limits=limits, seeds=seeds, run_seconds=run_seconds,
                            max_sample_iterations=max_sample_iterations)
    if not result.ok:
        raise SandboxError(f"{name} failed its sandboxed check: {result.message}", result)
    if record is not None:
        try:
            record.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(record, json.dumps(result.as_dict()), fsync=False)
        except OSError:
            pass  # the cache is only an optimisation
    return result
