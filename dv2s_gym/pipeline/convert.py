"""``dv2s convert``: video -> description -> Scenic script -> validated scenario (-> bank).

The output folder of one conversion holds, side by side::

    description.txt    the DRA's description (edit it and run `dv2s generate --from` to regenerate)
    elements.json      its semantic elements
    scenario.scenic    the generated script
    preview.webm       a rendered episode of the generated scenario
    report.json        safety, compile, sample and run checks, SP (and E2E-SC when labels exist),
                       warnings and provenance
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional
import datetime

from dv2s_gym.pipeline.errors import ConversionFolderError
from dv2s_gym.pipeline.llm_config import LLMConfig, LLMConfigLike
from dv2s_gym.pipeline.sg.openai import classify_failure
from scenario_bank.atomic import atomic_write_text, staged_folder
from dv2s_gym.pipeline.stages import Description, Generation, describe, generate
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from envs.recording import VideoWriter
from scenario_bank.safety import UnsafeScenarioError
from scenario_bank.sandbox import SandboxError, verify_script
from dv2s_gym.pipeline.labels import label_path_for, read_label
from dv2s_gym.pipeline.metrics import e2e_sc, semantic_preservation
from scenario_bank.bank import Bank, Provenance, Sidecar
from scenario_bank.elements import Elements
from scenario_bank.run_identity import CONVERSION_KIND, check_run_kind

__all__ = ["ConversionReport", "ConvertSettings", "ScenarioCheck", "UNPLACED_WARNING", "add_converted",
           "check_scenario", "checks_passed", "classify_failure", "generated", "placed_nothing", "conversion_provenance", "convert_video",
           "generate_to_folder", "label_for", "check_conversion_folder"]


@dataclass
class ScenarioCheck:
    """Validation of a generated script: each stage and what the simulation showed."""

    safe: bool = False
    safety_findings: List[str] = field(default_factory=list)
    compiled: bool = False
    sampled: bool = False
    ran: bool = False
    error: Optional[str] = None
    failure_category: Optional[str] = None
    simulated_elements: Optional[Elements] = None
    """What the simulated run showed (``None``: it did not run; written as ``{}``)."""
    episode: Dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.safe and self.compiled and self.sampled and self.ran

    def to_json(self) -> Dict[str, Any]:
        """The check as a conversion's ``report.json`` holds it, with ``ok``."""
        data = asdict(self)
        data["simulated_elements"] = {} if self.simulated_elements is None else self.simulated_elements.to_dict()
        data["ok"] = self.ok
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "ScenarioCheck":
        """The check :meth:`to_json` wrote."""
        values = {key: value for key, value in data.items() if key != "ok"}
        simulated = values.get("simulated_elements")
        values["simulated_elements"] = Elements.from_dict(simulated) if simulated else None
        return cls(**values)


def check_scenario(script: str, *, seed: int = 0, seconds: float = 10.0, preview: Optional[Path] = None,
                   name: str = "generated", in_process: bool = True) -> ScenarioCheck:
    """Safety check, compile, sample, run (ego driven by its Scenic behaviour), optionally record a preview.

    The script is compiled, sampled and run once in the sandbox (:mod:`scenario_bank.sandbox`) before
    it runs in this process. ``in_process=False`` stops after the sandbox (which compiled, sampled and
    ran it): for callers that run the scenario themselves next (no preview, no simulated elements)."""
    from envs.dv2s_env import DV2SEnv
    check = ScenarioCheck()
    try:  # the allowlist, compilation, sampling and a short run, all in the jail (cached by script hash)
        verify_script(script, name=name)
    except UnsafeScenarioError as error:
        check.safety_findings = [str(f) for f in error.findings]
        check.error = error.args[0]
        check.failure_category = "unsafe_code"
        return check
    except SandboxError as error:
        check.safe = True
        check.compiled = error.stage in ("sample", "run")
        check.sampled = error.stage == "run"
        check.error = f"sandboxed check: {error.result.message}"
        check.failure_category = ("other" if error.limit in ("cpu", "memory", "wall")
                                  else classify_failure(error.result.message, error.stage))
        return check
    check.safe = True
    if not in_process:
        check.compiled = check.sampled = check.ran = True
        return check
    try:
        env = DV2SEnv(scenario=script, config={"duration": seconds, "ego_policy": "scenic",
                                               "terminate_on_collision": False, "terminate_off_road": False},
                      render_mode="rgb_array" if preview else None)
        check.compiled = True
        obs, info = env.reset(seed=seed)
        check.sampled = True
        writer = VideoWriter(preview, fps=env.config["policy_frequency"]) if preview else None
        if writer:
            writer.write(env.render())
        done, steps = False, 0
        while not done:
            obs, reward, terminated, truncated, info = env.step(1)
            done = terminated or truncated
            steps += 1
            if writer:
                writer.write(env.render())
        if writer:
            writer.close()
        check.ran = True
        check.simulated_elements = elements_from_trace(env.trace)
        check.episode = {"steps": steps, "collisions": info["collisions"], "scenic_status": info["scenic_status"],
                         "min_ttc": info["min_ttc"]}
        env.close()
    except Exception as error:  # any failure is reported and classified, never raised
        check.error = f"{type(error).__name__}: {error}"
        check.failure_category = classify_failure(error)
    return check


def label_for(video: Path) -> Optional[Elements]:
    """Ground-truth elements stored beside a video as ``<video stem>.label.json`` (either label
    format, see :mod:`dv2s_gym.pipeline.labels`), if any; a malformed label raises ``LabelError``."""
    path = label_path_for(video)
    if not path.is_file():
        return None
    return read_label(path).elements


UNPLACED_WARNING = "could not place"
"""How a generation's warning about a part of its description it left out starts (the rules SG's, one per part):
the SP of such a generation scores only the parts that were placed (:attr:`ConversionReport.partial_sp`)."""


@dataclass(frozen=True)
class ConversionReport:
    """What a conversion did (:func:`generate_to_folder`, :func:`convert_video`): the description, the generation
    (or why it failed), the script's checks and scores, the files written and the seconds taken.
    :meth:`to_json` is the folder's ``report.json``."""

    description: Description
    generation: Optional[Generation] = None
    """The generated script and its warnings (``None``: the generation failed, :attr:`generation_error`)."""
    generation_error: Optional[str] = None
    """Why the generation failed (``"<error type>: <message>"``), or ``None``."""
    generation_error_category: Optional[str] = None
    """That failure's category (:func:`classify_failure`), or ``None``."""
    check: Optional[ScenarioCheck] = None
    """The script's checks (``None``: no script was generated)."""
    sp: Optional[float] = None
    """Semantic preservation of the description in the simulated run (``None``: the script did not run)."""
    e2e_sc: Optional[float] = None
    """End-to-end semantic consistency with the video's label (``None``: no label, or the script did not run)."""
    seconds: float = 0.0
    """Seconds of the generation and its checks."""
    files: List[str] = field(default_factory=list)
    """The files of :data:`OUTPUT_FILES` written to the output folder."""
    seconds_total: Optional[float] = None
    """Seconds of the whole conversion, description included (``None``: not measured)."""

    @property
    def warnings(self) -> List[str]:
        """The generation's warnings (none when it failed)."""
        return list(self.generation.warnings) if self.generation is not None else []

    @property
    def partial_sp(self) -> bool:
        """Whether :attr:`sp` scores only the parts of the description that were placed: the generation left a part
        out (a warning starting with :data:`UNPLACED_WARNING`)."""
        return self.sp is not None and any(str(w).startswith(UNPLACED_WARNING) for w in self.warnings)

    def to_json(self) -> Dict[str, Any]:
        """The report as ``report.json`` holds it: ``description``, ``generation`` (``{"error", "category"}`` when
        it failed), ``check`` (with ``ok``), ``sp`` and ``e2e_sc`` when scored, ``seconds``, ``files`` and
        ``seconds_total`` when measured."""
        data: Dict[str, Any] = {"description": self.description.as_dict()}
        if self.generation_error is not None:
            data["generation"] = {"error": self.generation_error, "category": self.generation_error_category}
        elif self.generation is not None:
            data["generation"] = self.generation.as_dict()
        if self.check is not None:
            data["check"] = self.check.to_json()
        for key in ("sp", "e2e_sc"):
            if getattr(self, key) is not None:
                data[key] = getattr(self, key)
        data["seconds"] = self.seconds
        data["files"] = list(self.files)
        if self.seconds_total is not None:
            data["seconds_total"] = self.seconds_total
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "ConversionReport":
        """The report :meth:`to_json` wrote (a conversion folder's ``report.json``, read)."""
        generation = data.get("generation") or {}
        failed = "error" in generation
        check = data.get("check")
        return cls(description=Description.from_dict(data["description"]),
                   generation=None if failed or not generation else Generation.from_dict(generation),
                   generation_error=generation.get("error") if failed else None,
                   generation_error_category=generation.get("category") if failed else None,
                   check=None if check is None else ScenarioCheck.from_json(check),
                   sp=data.get("sp"), e2e_sc=data.get("e2e_sc"), seconds=data.get("seconds", 0.0),
                   files=list(data.get("files") or []), seconds_total=data.get("seconds_total"))


OUTPUT_FILES = ("description.txt", "elements.json", "scenario.scenic", "preview.webm", "report.json")
"""Files :func:`generate_to_folder` may write; the report's ``files`` lists those it did write."""


def _write(folder: Path, name: str, text: str) -> None:
    atomic_write_text(folder / name, text, fsync=False)


def check_conversion_folder(out: str | os.PathLike) -> None:
    """Refuse ``out`` as a conversion's folder when it holds a run of another kind (a mining, regression or training
    run, a loop: :data:`~scenario_bank.run_identity.RUN_KINDS`), whose ``report.json`` the conversion would write
    over; a folder an earlier conversion wrote is written over as always.

    Raises:
        ConversionFolderError: ``"<out> holds a regression run (its run.json), not a D-V2S conversion: pass another
            --out ..."``.
    """
    check_run_kind(Path(out), CONVERSION_KIND, error=ConversionFolderError)


def generate_to_folder(description: Description, out: Path, *, sg: str = "rules", seed: int = 0,
                       llm_config: LLMConfigLike = None, labels: Optional[Elements] = None,
                       seconds: float = 10.0, started: Optional[float] = None) -> ConversionReport:
    """SG + validation for a description; writes the folder's files (:data:`OUTPUT_FILES`) and returns the report.
    ``started``: the :func:`time.perf_counter` at which the whole conversion began (the report's ``seconds_total``
    counts from it; ``None``: no such field).

    The files are written beside ``out`` and moved into it together at the end (:func:`staged_folder`): a run that
    fails to write (a full disk) leaves ``out`` as it was, and a finished run leaves no file of an earlier one.

    Raises:
        ConversionFolderError: ``out`` holds a run of another kind (:func:`check_conversion_folder`).
    """
    check_conversion_folder(out)
    with staged_folder(out, OUTPUT_FILES) as stage:
        _write(stage, "description.txt", description.text.strip() + "\n")
        _write(stage, "elements.json", json.dumps(description.elements.to_dict(), indent=2) + "\n")
        report = _generate_in(stage, description, sg=sg, seed=seed, llm_config=llm_config, labels=labels,
                              seconds=seconds, started=started)
    return report


def _generate_in(stage: Path, description: Description, *, sg: str, seed: int, llm_config: LLMConfigLike,
                 labels: Optional[Elements], seconds: float, started: Optional[float]) -> ConversionReport:
    """:func:`generate_to_folder`'s work, its files written in ``stage``."""
    start = time.perf_counter()
    results: Dict[str, Any] = {}
    try:
        generation: Optional[Generation] = generate(description.text, backend=sg, seed=seed, llm_config=llm_config)
    except Exception as error:
        results.update(generation_error=f"{type(error).__name__}: {error}",
                       generation_error_category=classify_failure(error))
        generation = None
    if generation is not None:
        _write(stage, "scenario.scenic", generation.script)
        check = check_scenario(generation.script, seed=seed, seconds=seconds, preview=stage / "preview.webm")
        if check.ran:
            generation.note_simulated(check.simulated_elements)
        results.update(generation=generation, check=check)
        if check.ran:
            results["sp"] = semantic_preservation(description.elements, check.simulated_elements)
            if labels is not None:
                results["e2e_sc"] = e2e_sc(labels, check.simulated_elements)
    report = ConversionReport(
        description=description, **results, seconds=round(time.perf_counter() - start, 3),
        files=[name for name in OUTPUT_FILES if name == "report.json" or (stage / name).is_file()],
        seconds_total=None if started is None else round(time.perf_counter() - started, 3))
    _write(stage, "report.json", json.dumps(report.to_json(), indent=2, default=str) + "\n")
    return report


def checks_passed(report: ConversionReport) -> bool:
    """Whether a conversion's script passed its checks (safe, compiled, sampled, ran): what ``dv2s convert``'s
    exit status says."""
    return report.check is not None and report.check.ok


def placed_nothing(report: ConversionReport) -> bool:
    """Whether neither the description's elements nor the generated script hold anything but the ego: every
    phrase was left out (a partial description, with warnings, still counts as generated)."""
    described = report.description.elements
    intended = report.generation.intended_elements if report.generation is not None else None
    if report.generation_error is not None or intended is None:
        return False
    return (described in (None, Elements()) and set(intended.participants) <= {"ego"} and not intended.actions)


def generated(report: ConversionReport) -> bool:
    """Whether a generation from a description succeeded (what ``dv2s generate``'s exit status says): its script
    passed its checks and something of the description was placed (:func:`placed_nothing`)."""
    return checks_passed(report) and not placed_nothing(report)


@dataclass(frozen=True)
class ConvertSettings:
    """How a video is converted (``dv2s convert``'s options; these defaults are its defaults)."""

    dra: str = "bev"
    """The Driving Record Analyzer backend (:func:`~dv2s_gym.pipeline.stages.describe`)."""
    sg: str = "rules"
    """The Scenario Generator backend (:func:`~dv2s_gym.pipeline.stages.generate`)."""
    camera: str = "bev"
    """What the video shows (``bev``: a bird's-eye view)."""
    question: Optional[str] = None
    """The question put to a VLM analyzer (``None``: its default)."""
    seed: int = 0
    """Seed of the generation and of the preview episode."""
    llm_config: Optional[LLMConfig] = None
    """Model settings of the LLM/VLM backends (a mapping of their keys is read into the record, its keys checked)."""
    seconds: float = 10.0
    """Length of the preview episode [s]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "llm_config", LLMConfig.of(self.llm_config))  # a mapping's keys checked once, here


def convert_video(video: str | os.PathLike, out: str | os.PathLike,
                  settings: Optional[ConvertSettings] = None) -> ConversionReport:
    """The whole pipeline for one video (with ``settings``, default :class:`ConvertSettings`); returns the report
    written to ``out/report.json``. ``out`` holding a run of another kind is refused before the video is read
    (:func:`check_conversion_folder`)."""
    start = time.perf_counter()
    check_conversion_folder(out)
    video, s = Path(video), settings or ConvertSettings()
    description = describe(video, backend=s.dra, camera=s.camera, question=s.question, llm_config=s.llm_config)
    report = generate_to_folder(description, Path(out), sg=s.sg, seed=s.seed, llm_config=s.llm_config,
                                labels=label_for(video), seconds=s.seconds, started=start)
    return report


def conversion_provenance(dra: str, sg: str, generation: Generation, description: Description) -> Dict[str, Any]:
    """The provenance fields every converted bank entry records: the backends (``generator``), the model and
    prompt context that made the script (from the generation, else the description) and today's date."""
    return {"generator": f"dra={dra},sg={sg}",
            "model": generation.model or description.model,
            "context_hash": generation.context_hash or description.prompt_hash,
            "date": datetime.date.today().isoformat()}


def add_converted(bank_dir: Optional[str | os.PathLike], video: str | os.PathLike, out: str | os.PathLike,
                  report: ConversionReport, *, seed: int, dra: str, sg: str) -> str:
    """Add the scenario a conversion wrote to ``out`` to the bank in ``bank_dir`` (the shipped bank, read-only, when
    None) with ``generated`` provenance; returns the entry's name, or a note saying why a conversion whose checks
    failed was not added."""
    if not checks_passed(report) or report.generation is None:
        return f"(not added: {video} failed validation)"
    description = report.description
    provenance = Provenance(kind="generated", video=str(video), seed=seed,
                            **conversion_provenance(dra, sg, report.generation, description))
    script = (Path(out) / "scenario.scenic").read_text(encoding="utf-8")
    entry = Bank(bank_dir).add(script, Sidecar(description=description.text, elements=description.elements,
                                               tags=("generated",), source=provenance))
    return entry.name
