"""A training run's folder: its ``run.json`` record (settings, identity, segments), its step checkpoints, and
what a resumed run reads back from them (settings, record, newest checkpoint, the scenario sampler's state)."""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, FrozenSet, List, Mapping, Optional, Sequence, Tuple

from policies.run_identity import CODE_IDENTITY, check_code_unchanged, code_identity
from policies.training.config import TrainConfig, TrainingError
from policies.training.scenario_envs import ScenarioSampler
from scenario_bank import select_scenarios
from scenario_bank.bank import Bank
from scenario_bank.atomic import atomic_write_json
from scenario_bank.records import JsonRecord, RecordError
from scenario_bank.run_identity import (BANK_IDENTITY, RunIdentityError, bank_identity, check_bank_unchanged,
                                        check_format, check_identity, check_run_kind, record_format)
from scenario_bank.run_paths import as_read, loop_folder, read_paths, record_paths, resume_fix

__all__ = [
    "TrainSegment",
    "TrainRun",
    "new_run_record",
    "write_run_record",
    "step_checkpoints",
    "latest_checkpoint",
    "load_run_config",
    "run_settings",
    "resolve_scenario_names",
    "open_run_record",
    "restored_sampler",
]


_RUN_SCHEMA = "dv2s-train-run"
_RUN_VERSION = 2
"""The format of a training run's ``run.json`` (bumped when its fields change; a run folder of another format is
refused on resume)."""


@dataclass(frozen=True, eq=False)
class TrainSegment(JsonRecord):
    """One stretch of a training run, between its start (or resume) and its end or interruption: a ``segments``
    item of ``run.json``. The steps it started and ended at (``start_step``, ``end_step``), how it ended
    (``status``: ``"finished"`` or ``"interrupted"``), its wall time ``wall_time_s`` [s] and the checkpoint it
    resumed from (``resumed_from``, ``null`` for a run's first segment). Other keys are kept in ``extra``."""

    start_step: int
    end_step: int
    status: str
    wall_time_s: float
    resumed_from: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("start_step", "end_step", "status", "wall_time_s")
    _WHAT: ClassVar[str] = "training segment"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"resumed_from"})

    @property
    def steps(self) -> int:
        """The steps the segment trained."""
        return self.end_step - self.start_step


@dataclass(frozen=True, eq=False)
class TrainRun(JsonRecord):
    """A training run's ``run.json``: its format (``schema``, ``version``), its settings (``config``,
    :meth:`~policies.training.config.TrainConfig.to_json`), the scripts of its scenarios (``bank_identity``,
    :func:`~scenario_bank.run_identity.bank_identity`), its code (``code_identity``,
    :func:`~policies.run_identity.code_identity`) and the segments trained so far (``segments``, each a
    :class:`TrainSegment`). Other keys are kept in ``extra``."""

    schema: str
    version: int
    config: Mapping[str, Any]
    bank_identity: Optional[Mapping[str, Any]] = None
    code_identity: Optional[Mapping[str, Any]] = None
    segments: Tuple[TrainSegment, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("schema", "version", "config")
    _WHAT: ClassVar[str] = "training run record"

    def with_segment(self, segment: TrainSegment) -> "TrainRun":
        """A copy with ``segment`` appended to its segments."""
        return self.replace(segments=self.segments + (segment,))


def new_run_record(config: TrainConfig, names: Sequence[str]) -> TrainRun:
    """A new run's ``run.json``: its format, its settings, the scripts of its scenarios ``names``
    (:func:`~scenario_bank.run_identity.bank_identity`), the code (:func:`~policies.run_identity.code_identity`: the
    files read in the run folder, the ``dv2s loop`` folder holding it and the bank are the run's own, not code) and no
    segment yet."""
    return TrainRun.from_dict({**record_format(_RUN_SCHEMA, _RUN_VERSION), "config": config.to_json(),
                               BANK_IDENTITY: bank_identity(Bank(config.bank_dir), names),
                               CODE_IDENTITY: code_identity(exclude=[config.out, loop_folder(config.out),
                                                                     config.bank_dir]),
                               "segments": []})


def write_run_record(path: Path, record: TrainRun) -> None:
    """Write ``run.json`` with the paths inside the run folder, or inside the loop folder holding it, relative to
    that folder (:mod:`scenario_bank.run_paths`: a moved run folder resumes where it is)."""
    atomic_write_json(path, record_paths(record.to_dict(), path.parent))


_CHECKPOINT = re.compile(r"^step_(\d+)\.zip$")


def step_checkpoints(directory: Path) -> List[Path]:
    """The ``step_<n>.zip`` checkpoints in ``directory``, oldest first (none when it is not a folder)."""
    if not directory.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in directory.iterdir() if (m := _CHECKPOINT.match(p.name))]
    return [p for _, p in sorted(found)]


def latest_checkpoint(out: os.PathLike | str) -> Optional[Path]:
    """The newest ``checkpoints/step_<n>.zip`` in a run folder, or ``None``."""
    found = step_checkpoints(Path(out) / "checkpoints")
    return found[-1] if found else None


def load_run_config(out: os.PathLike | str) -> Tuple[TrainConfig, TrainRun]:
    """The settings and the ``run.json`` record of the run in ``out`` (one of another format, :data:`_RUN_VERSION`,
    is refused)."""
    path = Path(out) / "run.json"
    check_run_kind(out, _RUN_SCHEMA, error=TrainingError)
    if not path.is_file():
        raise TrainingError(f"{out} holds no training run (no run.json); start one without --resume")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise TrainingError(f"{path} is not a readable run record ({error}); start a new run in another --out") from error
    check_format(record, _RUN_SCHEMA, _RUN_VERSION, folder=out, what="a training run", file=path.name,
                 error=TrainingError)
    record = read_paths(record, out)  # paths in the run (or its loop) folder where they are now
    try:
        run = TrainRun.from_dict(record)
        return TrainConfig.from_json(run.config), run
    except (RecordError, KeyError, TypeError) as error:
        raise TrainingError(f"{path} is not a readable run record ({error}); start a new run in another --out") from error


def run_settings(out: os.PathLike | str, given: Mapping[str, Any], resume: bool = False) -> TrainConfig:
    """The settings of the run in ``out``: ``given`` (settings by :class:`TrainConfig` field; ``None`` values are
    not given) over, when resuming, the settings the run recorded (:func:`load_run_config`), so a resumed run
    keeps what it was started with unless told otherwise."""
    settings = {key: value for key, value in given.items() if value is not None}
    if resume:
        recorded, _ = load_run_config(out)
        settings = {**recorded.to_json(), **settings}
    return TrainConfig.from_json({**settings, "out": str(out) if isinstance(out, Path) else out})


def resolve_scenario_names(config: TrainConfig) -> List[str]:
    """The run's scenarios, sorted: ``config.scenarios`` selected in its bank (an empty selection is refused)."""
    names = select_scenarios(config.scenarios, config.bank_dir)
    if not names:
        raise TrainingError("the scenario selection is empty; name bank scenarios or tag:<tag> after --scenarios")
    return sorted(names)


def _check_resume(config: TrainConfig, record: TrainRun, names: Sequence[str]) -> None:
    """Refuse ``config`` unless it has the identity of the run's ``record`` (``run.json``): its settings
    (``config``, :meth:`TrainConfig.to_json`'s form: a fine-tuning setting it leaves out is ``None`` on both sides),
    the scripts of its scenarios ``names`` and the code."""
    run = f"{config.out} holds a training run"
    check_identity(record.config, as_read(config.to_json(), config.out), TrainConfig.IDENTITY, run=run,
                   fix=resume_fix(config.out, "resume with the run's own settings (omit the option) or start a new "
                                              "run in another --out"))
    check_bank_unchanged(record.bank_identity, bank_identity(Bank(config.bank_dir), names), run=run)
    check_code_unchanged(record.to_dict(), run=run, error=RunIdentityError)


def open_run_record(config: TrainConfig, names: Sequence[str], resume: bool, log: Callable[[str], None]
                 ) -> Tuple[bool, TrainRun, Optional[Path]]:
    """``(resume, run.json's record, the newest checkpoint)`` of the run of the scenarios ``names`` in
    ``config.out``: a resumed run's record (checked against ``config``, the scripts and the code), or a new one
    (refused over an existing run)."""
    out = Path(config.out)
    check_run_kind(out, _RUN_SCHEMA, error=TrainingError)
    checkpoint = latest_checkpoint(out)
    record = new_run_record(config, names)
    if resume:
        _, record = load_run_config(out)
        _check_resume(config, record, names)
        if checkpoint is None:
            # stopped before its first checkpoint: nothing was kept, so the run starts over in place
            log(f"{out} holds no checkpoint yet (the run stopped before its first one): starting from step 0")
            resume, record = False, new_run_record(config, names)
        else:
            record = record.replace(config=config.to_json())
    elif checkpoint is not None or (out / "run.json").exists():
        at = f" (checkpoint at step {int(_CHECKPOINT.match(checkpoint.name).group(1))})" if checkpoint else ""
        raise TrainingError(f"{out} already holds a training run{at}; pass --resume to continue it, "
                            "or choose another --out")
    return resume, record, checkpoint


def restored_sampler(config: TrainConfig, names: Sequence[str],
                      checkpoint: Optional[Path]) -> Tuple[ScenarioSampler, int]:
    """The run's scenario sampler and the workers' seed stream: fresh, or as saved beside ``checkpoint``."""
    sampler = ScenarioSampler(names, config.sampler, config.weights, config.curriculum_floor, config.curriculum_window)
    if checkpoint is None:
        return sampler, 0
    sampler_state = checkpoint.with_suffix(".sampler.json")
    if sampler_state.is_file():
        sampler.load_state_dict(json.loads(sampler_state.read_text(encoding="utf-8")))
    return sampler, int(_CHECKPOINT.match(checkpoint.name).group(1))
