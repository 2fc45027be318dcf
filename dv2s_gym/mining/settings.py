"""What a mining run mines: :class:`MineSettings` (``dv2s mine``'s options and their defaults, in one place)."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from types import MappingProxyType
from typing import Any, Dict, List, Mapping, Optional, Tuple, Type, Union

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import DEFAULT_STALL_SECONDS, DEFAULT_TTC_THRESHOLD, MonitorSettings
from dv2s_gym.mining.sampling.samplers import default_feedback, registered_samplers
from scenario_bank.field_checks import (check_bool, check_int, check_mapping, check_names,
                                        check_number, check_path, check_text)
from scenario_bank.run_identity import recorded_settings, resume_keys, setting
from scenario_bank.run_paths import read_paths

__all__ = ["DEFAULT_BATCH", "FEEDBACKS", "MineSettings", "RunOrigin", "SETTINGS_FILE", "RunSettings",
           "read_run_settings"]

SETTINGS_FILE = "settings.json"
"""The file of a mining run folder that records what the run mines (:meth:`MineSettings.recorded` and the run's
resolved values)."""

FEEDBACKS = ("robustness", "novelty", "scenario-novelty", "state-novelty", "cluster-novelty")
"""What the adaptive samplers are fed: ``robustness`` (each episode's robustness) or ``novelty`` (the same,
except that a failure in a parameter cell an earlier episode already failed in with the same failure class,
:func:`~dv2s_gym.mining.cluster.cell_id`, is fed as an easy scene). Novelty is over where in parameter space
the sampler has found failures, not over the behaviour clusters the reports count. ``scenario-novelty``: only
the first failure of each scenario is fed as a failure, later ones as easy scenes (the sampler keeps looking in
scenarios that have not failed yet). ``state-novelty`` (``novelty-bandit``'s default): a failure is fed as one
only when its failure-state descriptor (:mod:`dv2s_gym.mining.failure_state`, continuous: speeds, geometry and
timing at the failure) is farther than :data:`~dv2s_gym.mining.failure_state.NOVELTY_RADIUS` from every earlier
failure's in the same scenario. ``cluster-novelty``: a failure is fed as one only when its behaviour cluster
(:func:`~dv2s_gym.mining.cluster.cluster_id`, the key the reports group failures by) is new to the run; a
failure in a cluster already found is fed as an easy scene."""


DEFAULT_BATCH = 8
"""Scenes drawn ahead of the outcomes fed back when ``--batch`` is not given. It is part of what the seed decides (an
adaptive sampler draws each scene after the outcomes of all but the last ``batch`` ones), so it is the same for any
number of workers: a run with more workers than this keeps the extra ones idle unless ``--batch`` is raised."""


@dataclasses.dataclass(frozen=True)
class MineSettings:
    """The settings of a mining run (:func:`dv2s_gym.mining.miner.mine`); the command line's defaults are these.

    A run folder records them (``settings.json``, :meth:`recorded`); resuming it needs the same ones
    (:meth:`resume_keys`) except ``budget`` (a larger one continues the run), ``convert``, ``conversion`` and
    ``max_conversions`` (not recorded).
    """

    budget: int = setting(200, resume=False)
    """Episodes to run in total (at least 1)."""
    sampler: str = "novelty-bandit"
    """One of :func:`~dv2s_gym.mining.sampling.samplers.registered_samplers` (``novelty-bandit``: broader failures than VerifAI's
    cross-entropy on the breadth bench, bench/RESULTS.md)."""
    sampler_options: Optional[Mapping[str, Any]] = setting(None, record=lambda options: dict(options or {}) or None)
    """Parameters of an adaptive sampler (VerifAI's ``alpha``, ``buckets``, ``thres``;
    :func:`~dv2s_gym.mining.sampling.samplers.sampler_params`); ``None``: the sampler's defaults."""
    feedback: Optional[str] = None
    """What the adaptive samplers learn from (:data:`FEEDBACKS`); ``None`` becomes the sampler's default
    (:func:`~dv2s_gym.mining.sampling.samplers.default_feedback`)."""
    scenarios: Optional[Tuple[str, ...]] = None
    """Bank names or ``tag:<tag>`` (``None``: the whole bank, or a resumed run's own)."""
    bank_dir: Optional[str] = None
    """The bank folder (``None``: the shipped bank); must be writable to ``convert``."""
    seed: int = 0
    """Seeds the sampler and every episode."""
    reference: Optional[str] = "rule"
    """The driver that decides avoidability (``None``: skip the check)."""
    batch: Optional[int] = None
    """Scenes drawn ahead of the outcomes fed back (default :data:`DEFAULT_BATCH`, or a resumed run's own)."""
    env_config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """DV2S-v0 config overrides."""
    ttc_threshold: float = DEFAULT_TTC_THRESHOLD
    """Time-to-collision [s] under which an episode is a low-TTC failure (:mod:`dv2s_gym.mining.monitors`)."""
    stall_seconds: float = DEFAULT_STALL_SECONDS
    """Seconds standing with a free lane ahead that count as a stall."""
    convert: bool = setting(False, resume=False, record=False)
    """Turn one failure per avoidable cluster into a bank scenario (:mod:`dv2s_gym.mining.conversion.convert`); ``bank_dir``
    must then be given and writable (a new or empty folder starts as a copy of the shipped bank)."""
    conversion: ConversionSettings = setting(default_factory=ConversionSettings, resume=False, record=False)
    """How failures are converted (:class:`~dv2s_gym.mining.conversion.settings.ConversionSettings`: the DRA and
    SG backends, ``k``...); the run's policy and ``env_config`` replace its own."""
    max_conversions: Optional[int] = setting(None, resume=False, record=False)
    """At most this many clusters are converted, largest first (``None``: all)."""

    def __post_init__(self) -> None:
        check_int(MiningError, "--budget", self.budget, low=1)
        if self.sampler not in registered_samplers():
            raise MiningError(f"unknown sampler {self.sampler!r}: use one of {', '.join(registered_samplers())}")
        check_mapping(MiningError, "--sampler-options", self.sampler_options, optional=True,
                      what="a JSON object of sampler parameters")
        if self.feedback is not None and not isinstance(self.feedback, str):
            raise MiningError(f"--feedback must be one of {', '.join(FEEDBACKS)} or left out, not {self.feedback!r}")
        object.__setattr__(self, "feedback", self.feedback or default_feedback(self.sampler))
        if self.feedback not in FEEDBACKS:
            raise MiningError(f"unknown feedback {self.feedback!r}: use one of {', '.join(FEEDBACKS)}")
        object.__setattr__(self, "scenarios", check_names(MiningError, "--scenarios", self.scenarios))
        check_path(MiningError, "--bank", self.bank_dir, optional=True)
        check_int(MiningError, "--seed", self.seed, low=0)
        check_text(MiningError, "--reference", self.reference, optional=True,
                   what="a driver's policy spec (e.g. rule)")
        check_mapping(MiningError, "--config", self.env_config, optional=True,
                      what="a JSON object of DV2S-v0 config overrides")
        object.__setattr__(self, "env_config", dict(self.env_config or {}))
        if self.batch == 0 and not isinstance(self.batch, bool):  # as the command line has always read it: the default
            object.__setattr__(self, "batch", None)
        check_int(MiningError, "--batch", self.batch, low=1, optional=True, none_means=f"{DEFAULT_BATCH}")
        check_bool(MiningError, "convert (--no-convert)", self.convert)
        if not isinstance(self.conversion, ConversionSettings):
            raise MiningError(f"conversion must be the conversion's settings (a ConversionSettings), not "
                              f"{self.conversion!r}")
        check_int(MiningError, "--max-conversions", self.max_conversions, low=0, optional=True,
                  none_means="all")
        # a NaN threshold would silently detect no failure, a negative one a stall at every standstill
        check_number(MiningError, "--ttc-threshold", self.ttc_threshold, low=0, interval="(]", example="seconds")
        check_number(MiningError, "--stall-seconds", self.stall_seconds, low=0, interval="(]", example="seconds")
        if self.convert and not self.bank_dir:
            raise MiningError("converting failures adds scenarios to a bank, and the shipped bank is read-only: "
                              "pass --bank DIR (a new folder starts as a copy of the shipped bank), or --no-convert")

    def replace(self, **changes: Any) -> "MineSettings":
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def resume_keys(cls) -> Tuple[str, ...]:
        """The settings a resumed run must share with the run it continues (every recorded one but ``budget``)."""
        return resume_keys(cls)

    def recorded(self) -> Dict[str, Any]:
        """The settings as ``settings.json`` records them (JSON values; ``sampler_options`` ``None`` when empty;
        the miner records the resolved ``batch``, ``scenarios`` and ``bank_dir`` over these)."""
        return recorded_settings(self)

    @property
    def monitor(self) -> MonitorSettings:
        """The failure monitors' settings (``ttc_threshold``, ``stall_seconds``)."""
        return MonitorSettings(ttc_threshold=float(self.ttc_threshold), stall_seconds=float(self.stall_seconds))

    def options(self) -> Dict[str, Any]:
        """The settings as keyword arguments of :class:`MineSettings` (``scenarios`` as a list)."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        values["scenarios"] = list(self.scenarios) if self.scenarios is not None else None
        return values


@dataclasses.dataclass(frozen=True)
class RunOrigin:
    """What started a mining run when another command derived its seed (``dv2s loop`` mines round ``round`` of a
    loop seeded ``seed``); ``settings.json`` records it as ``"origin"`` and the reports name it beside the run's own
    seed. Not a setting: a resumed run may be given another."""

    command: str
    """The command that started the run (e.g. ``"dv2s loop"``)."""
    seed: Optional[int] = None
    """That command's own seed."""
    round: Optional[int] = None
    """The command's round the run is part of."""

    def __post_init__(self) -> None:
        check_text(MiningError, "origin command", self.command, what="the name of the command that started the run")
        check_int(MiningError, "origin seed", self.seed, low=0, optional=True, none_means="not derived from one")
        check_int(MiningError, "origin round", self.round, low=1, optional=True, none_means="no round")

    def to_json(self) -> Dict[str, Any]:
        """The ``"origin"`` object of ``settings.json``."""
        return {"command": self.command, "seed": self.seed, "round": self.round}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "RunOrigin":
        """The origin an ``"origin"`` object records (checked as when made)."""
        return cls(command=data.get("command"), seed=data.get("seed"), round=data.get("round"))


class RunSettings:
    """A mining run's ``settings.json`` as read back (:func:`read_run_settings`), typed where the run's later steps
    read it (the policy, bank, env config, monitors, scenarios, batch, sampler and seed); :attr:`values` is the file
    as recorded (:meth:`MineSettings.recorded` with the policy, the resolved batch, scenarios and bank, the scene
    space and the schedule), which the resume identity check and the report that embeds the file read whole."""

    def __init__(self, path: Path, values: Mapping[str, Any]) -> None:
        self.path = path
        """The ``settings.json`` read."""
        self._values = dict(values)

    def __repr__(self) -> str:
        return f"RunSettings({str(self.path)!r}, {self._values!r})"

    @property
    def values(self) -> Mapping[str, Any]:
        """Every recorded value by its key, read-only (a data file's content: check a value before use)."""
        return MappingProxyType(self._values)

    @property
    def policy(self) -> Optional[str]:
        """The policy spec the run mined (data read from a file: check it before loading a policy from it)."""
        return self._values.get("policy")

    @property
    def bank_dir(self) -> Optional[str]:
        """The bank the run mined (``None``: the shipped bank)."""
        return self._values.get("bank_dir")

    @property
    def env_config(self) -> Any:
        """The DV2S-v0 config overrides the run recorded, as read (check them before use)."""
        return self._values.get("env_config")

    @property
    def monitor(self) -> MonitorSettings:
        """The failure monitors' settings the run recorded (``ttc_threshold``, ``stall_seconds``; the monitors'
        defaults for those absent)."""
        return MonitorSettings.from_recorded(self._values)

    @property
    def scenarios(self) -> Optional[List[str]]:
        """The scenarios the run mined, in the order of its scene space (``None``: the file lists none, which a
        run folder's resume refuses)."""
        scenarios = self._values.get("scenarios")
        return list(scenarios) if isinstance(scenarios, list) else None

    @property
    def batch(self) -> Optional[int]:
        """The scenes the run drew ahead of the outcomes fed back (``None``: not recorded)."""
        return self._values.get("batch")

    @property
    def sampler(self) -> Optional[str]:
        """The sampler the run drew scenes with."""
        return self._values.get("sampler")

    @property
    def schedule(self) -> Optional[str]:
        """How the run fed its sampler (``window`` or ``chunks``; ``None``: not recorded)."""
        return self._values.get("schedule")


def read_run_settings(run_dir: Union[str, os.PathLike], *,
                      error: Type[MiningError] = MiningError) -> Optional[RunSettings]:
    """The ``settings.json`` of the mining run in ``run_dir`` (``None`` when there is none); one that is not
    readable JSON or not a JSON object is refused with ``error`` in one line naming the file and the fix."""
    path = Path(run_dir) / SETTINGS_FILE
    if not path.is_file():
        return None
    fix = "restore it, or choose another --out (or delete the run folder) to start the run over"
    try:
        values = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as problem:
        raise error(f"{path} is not readable JSON ({problem}); {fix}") from None
    if not isinstance(values, dict):
        raise error(f"{path} is not a mining run's settings (a JSON {type(values).__name__}, not an object); {fix}")
    # the paths in the run folder, or in the loop folder that holds it, where they are now
    return RunSettings(path, read_paths(values, path.parent))
