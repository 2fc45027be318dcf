"""What a mining run mines: :class:`MineSettings` (``dv2s mine``'s options and their defaults, in one place)."""

from __future__ import annotations

import dataclasses
from typing import Any, Dict, Mapping, Optional, Tuple

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import DEFAULT_STALL_SECONDS, DEFAULT_TTC_THRESHOLD
from dv2s_gym.mining.samplers import default_feedback, registered_samplers

__all__ = ["FEEDBACKS", "MineSettings"]

FEEDBACKS = ("robustness", "novelty", "scenario-novelty", "state-novelty")
"""What the adaptive samplers are fed: ``robustness`` (each episode's robustness) or ``novelty`` (the same,
except that a failure in a parameter cell an earlier episode already failed in with the same failure class,
:func:`~dv2s_gym.mining.cluster.cell_id`, is fed as an easy scene). Novelty is over where in parameter space
the sampler has found failures, not over the behaviour clusters the reports count. ``scenario-novelty``: only
the first failure of each scenario is fed as a failure, later ones as easy scenes (the sampler keeps looking in
scenarios that have not failed yet). ``state-novelty`` (``novelty-bandit``'s default): a failure is fed as one
only when its failure-state descriptor (:mod:`dv2s_gym.mining.failure_state`, continuous: speeds, geometry and
timing at the failure) is farther than :data:`~dv2s_gym.mining.failure_state.NOVELTY_RADIUS` from every earlier
failure's in the same scenario."""


@dataclasses.dataclass(frozen=True)
class MineSettings:
    """The settings of a mining run (:func:`dv2s_gym.mining.miner.mine`); the command line's defaults are these.

    A run folder records them (``settings.json``); resuming it needs the same ones except ``budget`` (a larger
    one continues the run), ``convert``, ``convert_options`` and ``max_conversions``.
    """

    budget: int = 200
    """Episodes to run in total (at least 1)."""
    sampler: str = "novelty-bandit"
    """One of :data:`~dv2s_gym.mining.samplers.SAMPLERS` (``novelty-bandit``: broader failures than VerifAI's
    cross-entropy on the breadth bench, bench/RESULTS.md)."""
    sampler_options: Optional[Mapping[str, Any]] = None
    """Parameters of an adaptive sampler (VerifAI's ``alpha``, ``buckets``, ``thres``;
    :func:`~dv2s_gym.mining.samplers.sampler_params`); ``None``: the sampler's defaults."""
    feedback: Optional[str] = None
    """What the adaptive samplers learn from (:data:`FEEDBACKS`); ``None`` becomes the sampler's default
    (:func:`~dv2s_gym.mining.samplers.default_feedback`)."""
    scenarios: Optional[Tuple[str, ...]] = None
    """Bank names or ``tag:<tag>`` (``None``: the whole bank, or a resumed run's own)."""
    bank_dir: Optional[str] = None
    """The bank folder (``None``: the shipped bank); must be writable to ``convert``."""
    seed: int = 0
    """Seeds the sampler and every episode."""
    reference: Optional[str] = "rule"
    """The driver that decides avoidability (``None``: skip the check)."""
    batch: Optional[int] = None
    """Scenes drawn ahead of the outcomes fed back (default 4 per worker, or a resumed run's own)."""
    env_config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """DV2S-v0 config overrides."""
    ttc_threshold: float = DEFAULT_TTC_THRESHOLD
    """Time-to-collision [s] under which an episode is a low-TTC failure (:mod:`dv2s_gym.mining.monitors`)."""
    stall_seconds: float = DEFAULT_STALL_SECONDS
    """Seconds standing with a free lane ahead that count as a stall."""
    convert: bool = False
    """Turn one failure per avoidable cluster into a bank scenario (:mod:`dv2s_gym.mining.convert`); ``bank_dir``
    must then be given and writable (a new or empty folder starts as a copy of the shipped bank)."""
    convert_options: Optional[Mapping[str, Any]] = None
    """Keyword arguments of :func:`~dv2s_gym.mining.convert.convert_failure` (DRA and SG backends, ``k``...)."""
    max_conversions: Optional[int] = None
    """At most this many clusters are converted, largest first (``None``: all)."""

    def __post_init__(self) -> None:
        if isinstance(self.budget, bool) or not isinstance(self.budget, int) or self.budget < 1:
            raise MiningError(f"--budget must be at least 1 episode, not {self.budget}")
        if self.sampler not in registered_samplers():
            raise MiningError(f"unknown sampler {self.sampler!r}: use one of {', '.join(registered_samplers())}")
        object.__setattr__(self, "feedback", self.feedback or default_feedback(self.sampler))
        if self.feedback not in FEEDBACKS:
            raise MiningError(f"unknown feedback {self.feedback!r}: use one of {', '.join(FEEDBACKS)}")
        if self.scenarios is not None:
            object.__setattr__(self, "scenarios", tuple(str(name) for name in self.scenarios))
        object.__setattr__(self, "env_config", dict(self.env_config or {}))
        if self.batch == 0:  # as the command line has always read it: the default
            object.__setattr__(self, "batch", None)
        if self.batch is not None and (isinstance(self.batch, bool) or not isinstance(self.batch, int)
                                       or self.batch < 1):
            raise MiningError(f"--batch must be at least 1, not {self.batch}")
        if self.max_conversions is not None and (isinstance(self.max_conversions, bool)
                                                 or not isinstance(self.max_conversions, int)
                                                 or self.max_conversions < 0):
            raise MiningError(f"--max-conversions must be a whole number >= 0 or left out for all, "
                              f"not {self.max_conversions!r}")
        if self.convert and not self.bank_dir:
            raise MiningError("converting failures adds scenarios to a bank, and the shipped bank is read-only: "
                              "pass --bank DIR (a new folder starts as a copy of the shipped bank), or --no-convert")

    def replace(self, **changes: Any) -> "MineSettings":
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def options(self) -> Dict[str, Any]:
        """The settings as keyword arguments of :class:`MineSettings` (``scenarios`` as a list)."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        values["scenarios"] = list(self.scenarios) if self.scenarios is not None else None
        return values
