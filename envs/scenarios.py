"""Compile Scenic scenarios for highway-env, once per process, with clear errors.

A scenario can be given as a bank name, a path to a ``.scenic`` file or Scenic
source text. It is compiled against our highway-env world model (as Scenic's
``--model`` option does), in 2D mode; a script whose ``model`` line names Scenic's
CARLA or MetaDrive model compiles against the façade of that model
(:data:`FOREIGN_MODELS`, extending ours), other simulators' scripts run as long as
they only use driving-domain features.
"""

from __future__ import annotations

import hashlib
import os
import random
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple
import stat

import numpy as np

from envs.errors import ScenarioCompileError, SceneSamplingError, StepTimeoutError, UnsupportedConstructError, UntrustedScenarioError
from scenario_bank.safety import UnsafeScenarioError, check_script
from scenario_bank.scenic_parse import install_parse_cache
from envs.scenic_imports import no_folder_imports
from scenario_bank.maps import resolve_map
from scenario_bank.precheck import MAX_SCRIPT_BYTES, precheck_text
from scenario_bank.scenic2 import looks_like_scenic2, upgrade_scenic2
from scenario_bank.shipped import is_shipped_text
from scenario_bank.errors import MissingFileError

__all__ = ["MODEL", "CompiledScenario", "ParamRange", "parameter_ranges", "compile_scenario", "model_for", "FOREIGN_MODELS", "looks_like_source", "runtime_construct_error", "step_timeout_error", "read_scenario_file"]

MODEL = "envs.scenic_highway.model"
"""The Scenic world model every scenario is compiled against."""

FOREIGN_MODELS = {
    "carla": "envs.scenic_highway.carla.model",
    "metadrive": "envs.scenic_highway.metadrive.model",
}
"""Façade world models for scripts whose ``model`` line names another simulator's model."""

_OTHER_SIMULATORS = ("carla", "metadrive", "lgsvl", "webots", "airsim", "gta", "newtonian")


def looks_like_source(text: str) -> bool:
    """True when a scenario argument is Scenic source text rather than a name or path."""
    return "\n" in text or bool(re.search(r"\b(new|ego|param|model)\b.*[=\s]", text)) and " " in text


@dataclass
class CompiledScenario:
    """A compiled Scenic scenario and where it came from."""

    name: str
    source: str
    scenario: Any
    path: Optional[str] = None
    map_override: Optional[str] = None
    digest: str = ""
    origin: Optional[str] = None
    """The file an in-memory ``source`` came from (e.g. upgraded from Scenic 2), when not ``path``."""
    _diagnosis_cache: Dict[str, int] = field(default_factory=dict)
    last_iterations: int = 0
    """Rejection-sampling iterations the last :meth:`sample` needed (1 = accepted at once)."""

    @property
    def label(self) -> str:
        """What errors name: the file compiled, the file the source came from, or the name."""
        return self.path or self.origin or self.name

    @property
    def map_path(self) -> str:
        """Path of the OpenDRIVE map the scenario uses."""
        return str(self.scenario.params["map"])

    def parameter_ranges(self) -> Dict[str, "ParamRange"]:
        """The script's random global parameters that :meth:`sample` can fix, by name.

        ``param x = Range(a, b)`` gives a continuous range, ``DiscreteRange(a, b)`` an
        integer one, ``Uniform(...)`` over constants a choice. Other distributions
        (``Normal``, expressions of other random values) are left to the seed.
        """
        return parameter_ranges(self.scenario.params)

    def sample(self, seed: int, max_iterations: int = 2000, params: Optional[Dict[str, Any]] = None):
        """Sample a scene with Scenic's rejection sampler, seeded; raises :class:`SceneSamplingError`.

        ``params`` fixes global parameters (see :meth:`parameter_ranges`) to the given
        values for this sample only: every object and behaviour that depends on them sees the value.
        """
        from scenic.core.distributions import RejectionException

        random.seed(seed)
        np.random.seed(seed % (2**32))
        self._restart_external_sampler(seed)
        restore = self._condition(params or {})
        try:
            scene, self.last_iterations = self.scenario.generate(maxIterations=max_iterations, verbosity=0)
        except RejectionException:
            reasons = self.diagnose_rejections(seed)
            top = ", ".join(f"{r!r} ({n}x)" for r, n in reasons.most_common(3)) or "unknown"
            raise SceneSamplingError(
                f"scenario {self.name!r}: no scene satisfied its requirements in {max_iterations} "
                f"sampling iterations. Most frequent rejections: {top}. Loosen that requirement, "
                "widen the ranges it depends on, or raise config['max_sample_iterations']."
            ) from None
        finally:
            restore()
        return scene

    def _restart_external_sampler(self, seed: int) -> None:
        """Give the script's external parameters (``VerifaiRange`` ...) a sampler decided by ``seed`` alone.

        Scenic keeps one external sampler per compiled scenario, and its default (VerifAI's Halton sequence)
        hands out the next point of the sequence at each draw: the values would depend on how many scenes the
        compiled (and cached) scenario gave before in this process. A fresh sampler per scene, built after the
        seeding, with a Halton sequence started at ``seed``, makes the same (script, seed) the same scene in any
        process and order; consecutive seeds still walk the Halton sequence."""
        scenario = self.scenario
        if not getattr(scenario, "externalParams", None):
            return
        scenario.resetExternalSampler()
        for halton in _halton_samplers(scenario.externalSampler):
            halton.sample_index += int(seed) % _HALTON_START_PERIOD

    def _condition(self, params: Dict[str, Any]):
        """Condition global parameters to constants; returns the function that undoes it."""
        from scenic.core.distributions import ConstantSamplable

        if not params:
            return lambda: None
        ranges = self.parameter_ranges()
        unknown = sorted(set(params) - set(ranges))
        if unknown:
            raise SceneSamplingError(
                f"scenario {self.name!r} has no random global parameter {', '.join(map(repr, unknown))}; "
                f"the parameters that can be fixed are: {', '.join(sorted(ranges)) or 'none'}"
            )
        saved = []
        for key, value in params.items():
            distribution = self.scenario.params[key]
            ranges[key].check(key, value, self.name)
            saved.append((distribution, distribution._conditioned))
            distribution.conditionTo(ConstantSamplable(value))

        def restore() -> None:
            for distribution, previous in saved:
                distribution._conditioned = previous

        return restore

    def diagnose_rejections(self, seed: int, trials: int = 200) -> Counter:
        """Sample ``trials`` times without the requirements and count which one rejects."""
        from scenic.core.distributions import RejectionException, Samplable

        random.seed(seed)
        np.random.seed(seed % (2**32))
        self._restart_external_sampler(seed)
        reasons: Counter = Counter()
        scenario = self.scenario
        for _ in range(trials):
            try:
                if scenario.externalSampler is not None:
                    scenario.externalSampler.sample(None)
                sample = Samplable.sampleAll(scenario.dependencies)
            except RejectionException as error:
                reasons[_short(str(error))] += 1
                continue
            rejection = scenario.checker.checkRequirements(sample)
            if rejection is not None:
                reasons[_short(str(rejection))] += 1
        return reasons


_HALTON_START_PERIOD = 2**31
"""Seeds start the Halton sequence of external parameters at ``seed`` modulo this."""


def _halton_samplers(sampler: Any) -> List[Any]:
    """The VerifAI Halton samplers inside Scenic's external ``sampler`` (a VerifAI feature sampler wraps
    per-domain samplers, which may split into further ones)."""
    from verifai.samplers.halton import HaltonSampler

    found: List[Any] = []
    pending, seen = [sampler], set()
    while pending:
        current = pending.pop()
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        if isinstance(current, HaltonSampler):
            found.append(current)
            continue
        for attribute in ("sampler", "domainSampler", "lengthSampler", "samplers"):
            inner = getattr(current, attribute, None)
            if isinstance(inner, dict):
                pending.extend(inner.values())
            elif isinstance(inner, (list, tuple)):
                pending.extend(inner)
            elif inner is not None and not isinstance(inner, (str, int, float)):
                pending.append(inner)
    return found


@dataclass(frozen=True)
class ParamRange:
    """The values a random global parameter can take.

    ``kind`` is ``"continuous"`` (``low``..``high``), ``"integer"`` (``low``..``high``,
    whole numbers) or ``"choice"`` (one of ``values``).
    """

    kind: str
    low: float = 0.0
    high: float = 0.0
    values: Tuple[Any, ...] = ()

    def from_unit(self, u: float) -> Any:
        """The value at position ``u`` in [0, 1] of the range (samplers work on a unit box)."""
        u = min(max(float(u), 0.0), 1.0)
        if self.kind == "continuous":
            return self.low + u * (self.high - self.low)
        if self.kind == "integer":
            return int(min(self.high, self.low + int(u * (self.high - self.low + 1))))
        return self.values[min(len(self.values) - 1, int(u * len(self.values)))]

    def to_unit(self, value: Any) -> float:
        """Inverse of :meth:`from_unit` (the centre of the value's cell for discrete kinds)."""
        if self.kind == "continuous":
            return 0.0 if self.high == self.low else (float(value) - self.low) / (self.high - self.low)
        if self.kind == "integer":
            return (float(value) - self.low + 0.5) / (self.high - self.low + 1)
        return (self.values.index(value) + 0.5) / len(self.values)

    def check(self, name: str, value: Any, scenario: str) -> None:
        """Raise :class:`SceneSamplingError` when ``value`` is outside the range."""
        if self.kind == "choice":
            ok = value in self.values
        else:
            try:
                ok = self.low - 1e-9 <= float(value) <= self.high + 1e-9
            except (TypeError, ValueError):
                ok = False
        if not ok:
            allowed = (", ".join(map(repr, self.values)) if self.kind == "choice"
                       else f"{self.low:g}..{self.high:g}")
            raise SceneSamplingError(
                f"scenario {scenario!r}: parameter {name!r} = {value!r} is outside its range ({allowed}); "
                "pass a value inside it"
            )

    def as_dict(self) -> Dict[str, Any]:
        """JSON-safe form."""
        if self.kind == "choice":
            return {"kind": self.kind, "values": list(self.values)}
        return {"kind": self.kind, "low": self.low, "high": self.high}


def parameter_ranges(params: Dict[str, Any]) -> Dict[str, ParamRange]:
    """The :class:`ParamRange` of every global parameter in ``params`` that has one."""
    from scenic.core.distributions import DiscreteRange, Options, Range

    ranges: Dict[str, ParamRange] = {}
    for key, value in params.items():
        kind = type(value)
        if kind is Range and _constant(value.low) and _constant(value.high):
            ranges[key] = ParamRange("continuous", float(value.low), float(value.high))
        elif kind is DiscreteRange and value.weights is None and _constant(value.low) and _constant(value.high):
            ranges[key] = ParamRange("integer", int(value.low), int(value.high))
        elif kind is Options and value.options and all(_constant(o) for o in value.options):
            ranges[key] = ParamRange("choice", values=tuple(value.options))
    return ranges


def _constant(value: Any) -> bool:
    return isinstance(value, (int, float, str, bool))


def _short(text: str, limit: int = 160) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


_CACHE: Dict[Tuple[str, Optional[str]], CompiledScenario] = {}


def compile_scenario(
    source: str,
    *,
    name: str = "<string>",
    path: Optional[str] = None,
    map_override: Optional[str] = None,
    params: Optional[Dict[str, Any]] = None,
    origin: Optional[str] = None,
    trusted: bool = False,
) -> CompiledScenario:
    """Compile Scenic ``source`` against the highway-env model (cached per process).

    ``path``: the file ``source`` was read from; ``localPath`` resolves against its folder and
    errors name it, but the file is never read again: the text compiled is exactly the text
    checked (a file swapped after the check is not what runs). ``origin``: the file ``source``
    was derived from (e.g. upgraded from Scenic 2 syntax), used the same way.

    Only the package's own scripts (by content hash), scripts inside the jail and
    scripts the caller vouches for (``trusted=True``) are compiled; any other text
    raises :class:`UntrustedScenarioError`: run it through ``DV2SEnv`` (which
    jails it) or :func:`scenario_bank.sandbox.verify_script`.

    Raises :class:`ScenarioCompileError` with Scenic's message, the file and the
    line, or :class:`UnsupportedConstructError` when the script relies on
    something only another simulator provides.
    """
    if not (trusted or os.environ.get("DV2S_IN_JAIL") == "1"):
        if not is_shipped_text(source):
            raise UntrustedScenarioError(
                f"{path or origin or name}: refusing to compile a script that does not ship with dv2s-gym in this "
                "process; untrusted Scenic runs only in the jail (DV2SEnv / gym.make run it there). "
                "Pass trusted=True only for a script you wrote or reviewed")
    import scenic

    from envs.scenic_highway.stepping import release_veneer

    overrides = dict(params or {})
    if map_override is not None:
        overrides["map"] = str(resolve_map(map_override))
    digest = hashlib.sha256(
        (source + repr(sorted(overrides.items(), key=lambda kv: kv[0]))).encode()
    ).hexdigest()
    key = (digest, path or origin)
    if key in _CACHE:
        return _CACHE[key]
    label = path or origin or name
    # Every script is untrusted until the allowlist has read it, bank scenarios included (they passed it
    # when added, but the folder may have been edited since); the check shares the compiler's parse.
    # A script the parser cannot read is left to the compiler, whose error names the line.
    findings = [f for f in check_script(source, absolute_maps=True) if f.construct != "syntax"]
    if findings:
        raise UnsafeScenarioError(findings, label)
    release_veneer()
    install_parse_cache()
    model = model_for(source)
    try:
        # Scenic's localPath resolves against the folder of the compiled code's file name
        filename = os.path.realpath(path) if path is not None else origin or name
        with no_folder_imports():
            scenario = scenic.scenarioFromString(source, params=overrides, model=model, mode2D=True,
                                                 filename=filename)
    except Exception as error:  # Scenic raises many kinds; all become one clear error
        raise _compile_error(error, source, label) from None
    compiled = CompiledScenario(
        name=name, source=source, scenario=scenario, path=path, map_override=map_override, digest=digest,
        origin=origin,
    )
    _CACHE[key] = compiled
    return compiled


def runtime_construct_error(error: NameError, compiled: CompiledScenario) -> ScenarioCompileError:
    """The error to raise when a running behaviour uses a name nothing defines.

    Names inside behaviours are only looked up when the simulation runs, so a
    CARLA-only action (``SetAutopilotAction``...) surfaces at ``reset``/``step``;
    it gets the same :class:`UnsupportedConstructError` as at compile time.
    """
    return _compile_error(error, compiled.source, compiled.label)


def step_timeout_error(overtime: Exception, compiled: CompiledScenario) -> StepTimeoutError:
    """The error for a simulation step that ran over the env's ``step_time_limit``, naming the
    script lines that were running: the outermost frame of the script (the behaviour whose loop
    never ends its step) and, inside it, where the CPU limit caught it."""
    label = compiled.label
    lines = _script_lines(overtime, label)
    where = f"{label}, line {lines[0]}" if lines else label
    code = f"`{_source_line(compiled.source, lines[0])}`" if lines else "a behaviour"
    inner = [line for line in dict.fromkeys(lines[1:]) if line != lines[0]]
    if inner:
        code += ", inside it " + ", ".join(f"line {n} `{_source_line(compiled.source, n)}`" for n in inner)
    return StepTimeoutError(
        f"{where}: one simulation step used over {getattr(overtime, 'seconds', 0):g} s of CPU in {code}: a behaviour that "
        "loops without taking an action (e.g. `while True: do B()` where B returns at once) never ends its time "
        "step. Make each pass of the loop take an action or `wait`; raise the env's `step_time_limit` if the step "
        "is only slow.")


def _script_lines(error: BaseException, label: str) -> List[int]:
    """The lines of the frames of ``error``'s traceback that run the script ``label``, outermost first."""
    lines = []
    tb = error.__traceback__
    while tb is not None:
        if tb.tb_frame.f_code.co_filename in (label, os.path.realpath(label)):
            lines.append(tb.tb_lineno)
        tb = tb.tb_next
    return lines


def _innermost_script_line(error: BaseException, label: str) -> Optional[int]:
    """The line of the innermost frame of ``error``'s traceback that runs the script ``label``."""
    lines = _script_lines(error, label)
    return lines[-1] if lines else None


def _compile_error(error: Exception, source: str, label: str) -> ScenarioCompileError:
    from envs.scenic_highway.model_support import MissingMapError

    message = str(error).strip() or type(error).__name__
    line = getattr(error, "lineno", None)
    if line is None:
        line = _innermost_script_line(error, label)
    column, quoted = _syntax_position(error, line)
    where = (f"{label}, line {line}" + (f", column {column}" if column else "")) if line else label
    if isinstance(error, MissingMapError):
        return ScenarioCompileError(f"{where}: {message}", path=label, line=line)
    if isinstance(error, FileNotFoundError) or type(error).__name__ == "UnknownMapError":
        return ScenarioCompileError(f"{where}: map not found: {message}", path=label, line=line)
    map_file = _map_being_loaded(error)
    if map_file is not None:
        return ScenarioCompileError(
            f"{where}: the map {map_file!r} failed to load: {type(error).__name__}: {message}. "
            "Check that it is a valid OpenDRIVE file, or set `param map` to a shipped map.",
            path=label,
            line=line,
        )
    if isinstance(error, KeyError) and re.fullmatch(r"'(road|lane|junction|intersection)?[\w.-]*'", message):
        return ScenarioCompileError(
            f"{where}: the map has no element `{message.strip(chr(39))}` (a road or lane id of another map?). "
            "Look elements up by position or use `Uniform(*network.roads)`, or set `param map` to the map "
            "the script was written for.",
            path=label,
            line=line,
        )
    undefined = re.search(r"name '([^']+)' is not defined", message)
    if undefined:
        construct = undefined.group(1)
        other = _mentions_other_simulator(source)
        hint = (
            f" The script targets {other}; `{construct}` is specific to that simulator and has no "
            "highway-env equivalent. Use driving-domain constructs (scenic.domains.driving) instead."
            if other
            else f" `{construct}` is not defined by Scenic's driving domain or the highway-env model; "
            "check its spelling or define it in the script."
        )
        return UnsupportedConstructError(
            f"{where}: unsupported construct `{construct}`.{hint}", path=label, line=line
        )
    if "Map" in type(error).__name__ or "xodr" in message.lower() or "opendrive" in message.lower():
        return ScenarioCompileError(
            f"{where}: the map failed to load: {message}. Check that `param map` names a valid "
            "OpenDRIVE file or a shipped map.",
            path=label,
            line=line,
        )
    if "discrete distribution over empty domain" in message:
        picked = _source_line(source, line)
        return ScenarioCompileError(
            f"{where}: `{picked}` picks from an empty set: nothing on this map matches what the script "
            "filters for (e.g. a 4-way intersection, a lane with a neighbour on its left). Use a map that "
            "has it (`param map`), or relax the filter.",
            path=label,
            line=line,
        )

    if looks_like_scenic2(source, message):
        first = upgrade_scenic2(source, keep_scenic2_meaning=False).rewrites[0]  # a construct Scenic 3 refuses
        return ScenarioCompileError(
            f"{where}: Scenic 2 syntax: `{first.before.strip()[:80]}` (line {first.line}): {first.why}. Upgrade the "
            "script: the env's config `upgrade_scenic2: True`, `Bank.add(..., upgrade_scenic2=True)` or "
            "`dv2s bank add`, which upgrade it and report each rewrite.",
            path=label,
            line=line,
        )
    return ScenarioCompileError(
        f"{where}: Scenic could not compile the scenario: {type(error).__name__}: {message}{quoted}",
        path=label,
        line=line,
    )


def _syntax_position(error: Exception, line: Optional[int]) -> Tuple[Optional[int], str]:
    """The column (1-based) of a syntax error and `` (the line: `...`; at `...`)`` quoting the script's line,
    when the parser gives them (``offset``, ``text``, ``end_offset`` of a ``SyntaxError``-like error)."""
    offset, text = getattr(error, "offset", None), getattr(error, "text", None)
    if not line or not isinstance(offset, int) or isinstance(offset, bool) or offset < 1:
        return None, ""
    if not isinstance(text, str) or not text.strip():
        return offset, ""
    raw = text.rstrip("\r\n")
    shown = " ".join(raw.split())[:120]
    end = getattr(error, "end_offset", None)
    part = ""
    if isinstance(end, int) and getattr(error, "end_lineno", line) == line and offset < end <= len(raw) + 1:
        part = " ".join(raw[offset - 1:end - 1].split())[:60]
    return offset, f" (the line: `{shown}`" + (f"; at `{part}`" if part else "") + ")"


def _source_line(source: str, line: Optional[int]) -> str:
    lines = source.splitlines()
    if line is None or not 1 <= line <= len(lines):
        return "a choice"
    return " ".join(lines[line - 1].split())[:80]


def _map_being_loaded(error: Exception) -> Optional[str]:
    """The map file Scenic was reading when ``error`` was raised, if it was reading one."""
    tb = error.__traceback__
    found = None
    while tb is not None:
        code = tb.tb_frame.f_code
        if (code.co_name == "fromFile" and code.co_filename.endswith(os.path.join("driving", "roads.py"))) or (
            code.co_name == "load_network" and code.co_filename.endswith(os.path.join("scenario_bank", "map_cache.py"))
        ):
            found = tb.tb_frame.f_locals.get("path", found)
        tb = tb.tb_next
    return None if found is None else str(found)


def model_for(source: str) -> str:
    """The world model a script compiles against: the CARLA or MetaDrive façade when its
    ``model`` line names ``scenic.simulators.carla.model`` / ``...metadrive.model``, else :data:`MODEL`."""
    match = re.search(r"^\s*model\s+scenic\.simulators\.(\w+)\.model\s*$", source, re.M)
    if match and match.group(1) in FOREIGN_MODELS:
        return FOREIGN_MODELS[match.group(1)]
    return MODEL


def _mentions_other_simulator(source: str) -> Optional[str]:
    match = re.search(r"^\s*model\s+scenic\.simulators\.(\w+)", source, re.M)
    if match and match.group(1) in _OTHER_SIMULATORS:
        return f"scenic.simulators.{match.group(1)}"
    return None


def read_scenario_file(path: str | os.PathLike) -> str:
    """Read a ``.scenic`` file, with a clear error when it is missing.

    Only a regular file is read, and no more than the precheck's size cap (one byte more, to
    tell a too-large file): a FIFO, a device or a huge file cannot hang or fill the process.
    The bytes then pass :func:`~scenario_bank.precheck.precheck_text` (strict UTF-8, no coding
    declaration but UTF-8, bounded lines and nesting).
    """
    file = Path(path)
    if not file.is_file():
        raise MissingFileError(f"scenario file {str(file)!r} does not exist")
    # O_NONBLOCK: a FIFO swapped in after is_file() does not block the open
    fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb") as stream:
        if not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
            raise MissingFileError(f"scenario file {str(file)!r} is not a regular file")
        data = stream.read(MAX_SCRIPT_BYTES + 1)
    return precheck_text(data, str(file))
