"""What a regression run compares on: :class:`RegressSettings`, and :class:`BaselineReport` for a baseline read
from an earlier run's report instead of run again."""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

from dv2s_gym.regress import stats
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.failures import DEFAULT_STALL_SECONDS, parse_failure
from envs.safety_metrics import MonitorSettings
from scenario_bank.field_checks import check_bool, check_int, check_mapping, check_names, check_number, check_path

__all__ = ["RegressSettings", "BaselineReport", "ROLES"]

ROLES = ("candidate", "baseline")
"""The two policies of a regression run."""


@dataclasses.dataclass(frozen=True)
class RegressSettings:
    """The settings of a regression run (:func:`dv2s_gym.regress.runner.run_regression`); ``dv2s regress``'s
    defaults are these. A run folder resumes only with the same ones (``run.json`` records them)."""

    scenarios: Optional[Tuple[str, ...]] = None
    """Bank names and/or ``tag:<tag>`` (``None``: the whole bank, or the baseline report's scenarios)."""
    bank_dir: Optional[str] = None
    """The bank folder (``None``: the shipped bank)."""
    episodes: Optional[int] = None
    """Seeds per scenario; episode ``k`` uses env seed ``seed + k`` (``None``: planned from ``mde`` and ``power``,
    :func:`dv2s_gym.regress.power.plan_episodes`, with the baseline report's failure rates when there is one)."""
    seed: int = 0
    """The first env seed."""
    margin: float = stats.DEFAULT_MARGIN
    """Non-inferiority margin on the failure-rate difference, in [0, 1) (the statistics are calibrated at the
    default 0.02 = 2 points: bench/calibrate_regress.py)."""
    alpha: float = 0.05
    """Level of the FAIL test (PASS is tested at ``alpha / 2``), strictly between 0 and 1."""
    mde: Optional[float] = None
    """The regression of one scenario's failure rate the run must FAIL (``None``: 0.30); chooses ``episodes``."""
    power: Optional[float] = None
    """The probability it does (``None``: 0.8); chooses ``episodes``."""
    sequential: bool = False
    """Stop as soon as a group-sequential test of the pooled table settles FAIL, looking after every ``batch``
    seeds; PASS is decided at the end. Needs a baseline."""
    batch: Optional[int] = None
    """Seeds between the sequential looks (``None``: a fifth of ``episodes``)."""
    env_config: Optional[Mapping[str, Any]] = None
    """``DV2S-v0`` config overrides for every episode (``None``: none, or the baseline report's)."""
    failure: Union[None, str, Sequence[str]] = None
    """What counts as a failure: kinds among ``collision``, ``off_road``, ``stall`` (a list or
    ``"collision,stall"``; ``None``: all three); each kind is also reported apart. Read as the kinds' tuple."""
    stall_seconds: float = DEFAULT_STALL_SECONDS
    """How long the ego must stand with a free road ahead for a stall."""

    @property
    def monitor(self) -> MonitorSettings:
        """The failure monitors' settings of the run (its ``stall_seconds``), as the run's code carries them."""
        return MonitorSettings(stall_seconds=float(self.stall_seconds))

    def __post_init__(self) -> None:
        object.__setattr__(self, "scenarios", check_names(RegressError, "--scenarios", self.scenarios))
        check_path(RegressError, "--bank", self.bank_dir, optional=True)
        check_int(RegressError, "--episodes", self.episodes, low=1, optional=True, none_means="planned from --mde")
        check_int(RegressError, "--seed", self.seed, low=0)
        check_number(RegressError, "--margin", self.margin, low=0, high=1, interval="[)",
                     example="a failure-rate difference, e.g. 0.05 for 5 points")
        check_number(RegressError, "--alpha", self.alpha, low=0, high=1, interval="()",
                     example="e.g. 0.05")
        check_number(RegressError, "--mde", self.mde, low=0, high=1, interval="()", optional=True)
        check_number(RegressError, "--power", self.power, low=0, high=1, interval="()",
                     optional=True)
        check_bool(RegressError, "--sequential", self.sequential)
        check_int(RegressError, "--batch", self.batch, low=1, optional=True, none_means="a fifth of the episodes")
        check_mapping(RegressError, "--config", self.env_config, optional=True,
                      what="a JSON object of DV2S-v0 config overrides")
        if self.failure is not None and not isinstance(self.failure, str):
            check_names(RegressError, "--failure", self.failure, optional=False)
        object.__setattr__(self, "failure", tuple(parse_failure(self.failure)))
        check_number(RegressError, "--stall-seconds", self.stall_seconds, low=0, interval="(]")

    def replace(self, **changes: Any) -> "RegressSettings":
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True)
class BaselineReport:
    """A baseline read from an earlier run's ``report.json``: the episodes of its ``role`` policy are the
    baseline's, so only the candidate runs. Refused when its schema version, the bank scenarios' scripts or
    the env config differ, and when its verdict was FAIL or ERROR unless ``accept_failed``."""

    path: Union[str, os.PathLike]
    """The report's ``report.json``."""
    role: str = "candidate"
    """Which of its policies is the baseline: ``candidate`` (the one it tested) or ``baseline``."""
    accept_failed: bool = False
    """Use it even when its own verdict was FAIL or ERROR (a measurement, not a gate)."""
