"""What a ``dv2s loop`` runs: :class:`LoopSettings` (its options and their defaults, in one place)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Tuple

from dv2s_gym.mining.sampling.samplers import registered_samplers
from envs.errors import DV2SError
from policies.card_record import FINE_TUNE_METHODS as CARD_FINE_TUNE_METHODS
from scenario_bank.run_identity import recorded_settings, resume_keys, setting
from scenario_bank.field_checks import (check_bool, check_choice, check_int, check_mapping, check_names,
                                        check_number, check_path)

__all__ = ["LoopError", "LoopSettings", "DEFAULTS", "FINE_TUNE_METHODS", "METHOD_LEARNING_RATES", "PROFILES",
           "DEFAULT_PROFILE", "EVIDENCE"]

FINE_TUNE_METHODS = CARD_FINE_TUNE_METHODS
"""How the loop fine-tunes: ``ppo`` continues PPO on the fine-tuning reward
(:func:`policies.training.fine_tune`); ``dagger`` imitates the reference driver on the
policy's own states (:func:`policies.imitation.dagger_fine_tune`)."""

METHOD_LEARNING_RATES = {"ppo": 1e-4, "dagger": 1e-3}
"""The fine-tuning learning rate when none is given: PPO's constant rate (its own 5e-4 made the
bank worse, bench/RESULTS.md) and DAgger's Adam rate."""


class LoopError(DV2SError, ValueError):
    """Bad loop input, or an ``out`` folder that holds no loop this version can resume."""


@dataclasses.dataclass(frozen=True)
class LoopSettings:
    """The settings of a loop (:func:`dv2s_gym.loop.run.run_loop`; module docstring of
    :mod:`dv2s_gym.loop.run` for the steps). The embedded defaults (the ``quick`` profile of :data:`PROFILES`)
    are small, sized for one round in about 5 minutes on 2 idle cores, mining, fine-tuning both arms and judging
    (``python -m bench.bench_loop`` times a round and bench/RESULTS.md records it): too few held-out episodes and
    families for a drop or a test, which the round says. :meth:`evidence` (``dv2s loop --profile evidence``)
    gives the larger round whose numbers can be judged. ``loop.json`` records the resolved values; a resumed loop
    needs the same ones except ``rounds`` (raise it to add rounds) and ``workers`` (runs are the same whatever
    the number of workers)."""

    rounds: int = setting(1, resume=False)
    """Rounds to have finished when the loop returns (a resumed loop runs only the missing ones)."""
    bank_dir: Optional[str] = setting(None, record=lambda path: None if path is None else str(Path(path).resolve()))
    """A writable bank to grow (``None``: a copy of the shipped bank in ``out/bank``)."""
    scenarios: Optional[Tuple[str, ...]] = None
    """The scenarios mined and regression-tested (``None``: the starting bank's)."""
    budget: int = 32
    """The miner's episodes per round."""
    sampler: str = "novelty-bandit"
    """The miner's sampler (:data:`dv2s_gym.mining.sampling.samplers.SAMPLERS`)."""
    max_conversions: Optional[int] = 1
    """Clusters converted into bank scenarios per round, largest first (``None``: all, 0: none)."""
    max_replays: Optional[int] = 6
    """Clusters beyond the converted ones whose failing scene is kept as an exact replay entry per round, the
    families taking turns, each its largest cluster first (:func:`dv2s_gym.loop.replays.replay_order`; ``None``:
    all, 0: none)."""
    holdout_fraction: float = 0.5
    """Share of the round's mined families held out from fine-tuning, in [0, 1]."""
    fine_tune_method: str = "dagger"
    """``ppo`` or ``dagger`` (:data:`FINE_TUNE_METHODS`)."""
    fine_tune_steps: int = 6_000
    """Env steps of fine-tuning per round."""
    fine_tune_lr: Optional[float] = None
    """The fine-tuning's (constant) learning rate; ``None`` becomes the method's
    (:data:`METHOD_LEARNING_RATES`)."""
    fine_tune_reward: Optional[Mapping[str, float]] = dataclasses.field(
        default_factory=lambda: {"standing": -0.3})
    """Reward-term weights overriding the policy's own in the fine-tuning env only (``{}``: the policy's reward
    unchanged; ``None``: the default); used by the ``ppo`` method only (imitation has no reward)."""
    dagger_beta_decay: float = 0.0
    """DAgger's ``beta_decay`` in both arms (:class:`~policies.dagger_config.DaggerConfig`), in [0, 1]: the reference
    driver drives the first iteration alone and each later one with probability ``beta_decay ** i``, the policy
    the rest (0, the default: the policy drives every later iteration, so each arm learns on the states its own
    driving reaches, the mined scenes' included; 0.5 left the two arms equal in the measured rounds, see
    ``docs/loop.md``); used by the ``dagger`` method only."""
    mined_share: float = 0.5
    """Probability of drawing a mined fine-tuning scenario during fine-tuning, strictly between 0 and 1."""
    control: bool = True
    """Also fine-tune without the mined scenarios (the control arm) and compare on held-out."""
    k_eval: int = 4
    """Evaluation seeds per held-out scenario."""
    min_heldout_episodes: int = 20
    """Below this many held-out episodes a round reports rates only, no drop and no test."""
    min_heldout_families: int = 3
    """Likewise below this many held-out families (the episodes of one family are near-identical scenes)."""
    untouched_seeds: int = 1
    """Seeds per scenario of the untouched set (:data:`dv2s_gym.loop.comparisons.UNTOUCHED_BANK`); 0 skips it."""
    regress_episodes: int = 1
    """Seeds per starting-bank scenario in the regression test."""
    margin: float = 0.02
    """The regression test's non-inferiority margin."""
    seed: int = 0
    """Seeds the miner, the split and the fine-tuning (each round derives its own)."""
    workers: Optional[int] = setting(None, resume=False)
    """Processes for mining and evaluation (``None``: every core)."""
    n_envs: int = 2
    """Training environments (subprocesses)."""

    def __post_init__(self) -> None:
        self._check_counts()
        self._check_shares()
        object.__setattr__(self, "scenarios", check_names(LoopError, "--scenarios", self.scenarios))
        check_path(LoopError, "--bank", self.bank_dir, optional=True)
        if self.fine_tune_reward is None:
            object.__setattr__(self, "fine_tune_reward", dict(DEFAULTS["fine_tune_reward"]))
        check_mapping(LoopError, "--fine-tune-reward", self.fine_tune_reward,
                      what="a JSON object of reward-term weights")
        for term, weight in self.fine_tune_reward.items():
            check_number(LoopError, f"--fine-tune-reward {term!r}", weight)
        check_bool(LoopError, "control (--no-control)", self.control)

        # else round 1 starts (the working bank copied) before the miner refuses it
        check_choice(LoopError, "--sampler", self.sampler, registered_samplers())
        check_choice(LoopError, "--fine-tune-method", self.fine_tune_method, FINE_TUNE_METHODS)
        if self.fine_tune_lr is None:
            object.__setattr__(self, "fine_tune_lr", METHOD_LEARNING_RATES[self.fine_tune_method])
        check_number(LoopError, "--fine-tune-lr", self.fine_tune_lr, low=0, interval="(]")

    def _check_counts(self) -> None:
        for name, low in (("rounds", 1), ("budget", 1), ("fine_tune_steps", 1), ("k_eval", 1),
                          ("regress_episodes", 1), ("min_heldout_episodes", 0), ("min_heldout_families", 0),
                          ("untouched_seeds", 0)):
            check_int(LoopError, f"--{name.replace('_', '-')}", getattr(self, name), low=low)
        # >= 0: each round seeds its miner and fine-tuning with seed * 1000 + round, which must not be negative
        check_int(LoopError, "--seed", self.seed, low=0)
        check_int(LoopError, "--envs", self.n_envs, low=1)
        check_int(LoopError, "--workers", self.workers, low=0, optional=True, none_means="every core")  # 0: every core
        check_int(LoopError, "--max-conversions", self.max_conversions, low=0, optional=True,
                  none_means="every cluster; 0: no conversions, only exact replays")
        check_int(LoopError, "--max-replays", self.max_replays, low=0, optional=True,
                  none_means="every cluster; 0: no replays beyond the converted clusters")

    def _check_shares(self) -> None:
        # the same range as the regression test's (RegressSettings), checked here because the loop reaches its
        # regression step only after a round's mining and fine-tuning, and ``margin`` is part of its identity
        check_number(LoopError, "--margin", self.margin, low=0, high=1, interval="[)",
                     example="a failure-rate difference, e.g. 0.05 for 5 points")
        check_number(LoopError, "--holdout-fraction", self.holdout_fraction, low=0, high=1, interval="(]",
                     example="e.g. 0.5: a round that holds nothing out can never be judged")
        check_number(LoopError, "--mined-share", self.mined_share, low=0, high=1, interval="()")
        check_number(LoopError, "--dagger-beta-decay", self.dagger_beta_decay, low=0, high=1)

    def replace(self, **changes: Any) -> "LoopSettings":
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def resume_keys(cls) -> Tuple[str, ...]:
        """The settings a resumed loop must share with the loop it continues: all but ``rounds`` and ``workers``."""
        return resume_keys(cls)

    def recorded(self) -> Dict[str, Any]:
        """The settings as ``loop.json`` records them (JSON values; ``bank_dir`` resolved to an absolute path)."""
        return recorded_settings(self)

    @classmethod
    def from_profile(cls, name: str = "quick", **overrides: Any) -> "LoopSettings":
        """The settings of profile ``name`` (:data:`PROFILES`), with ``overrides`` (explicit values) on top."""
        if name not in PROFILES:
            raise LoopError(f"--profile must be one of {', '.join(PROFILES)}, not {name!r}")
        return cls(**{**PROFILES[name], **overrides})

    @classmethod
    def evidence(cls, **overrides: Any) -> "LoopSettings":
        """The ``evidence`` profile (:data:`EVIDENCE`): a round large enough to judge, with ``overrides``."""
        return cls.from_profile("evidence", **overrides)


def _defaults() -> Dict[str, Any]:
    values: Dict[str, Any] = {}
    for field in dataclasses.fields(LoopSettings):
        if field.name in ("bank_dir", "scenarios", "workers", "n_envs"):
            continue
        values[field.name] = field.default_factory() if field.default is dataclasses.MISSING else field.default
    return values


DEFAULTS: Dict[str, Any] = _defaults()
"""The default of every loop option the command line takes as a flag of its own (read from
:class:`LoopSettings`)."""


EVIDENCE: Dict[str, Any] = {"budget": 240, "max_conversions": 4, "max_replays": 16, "fine_tune_steps": 40_000,
                            "k_eval": 10, "untouched_seeds": 5, "regress_episodes": 4}
"""The ``evidence`` profile's values where they differ from the defaults: the scale of the loop measurements in
bench/RESULTS.md (240 mining episodes, 40k DAgger steps per arm, 10 seeds per held-out scenario, 4 per bank
scenario), 4 conversions and 16 exact replays per round for held-out families, 5 seeds per untouched scenario.
About 23 minutes for one round on 2 shared cores (load 4-8), as measured in bench/RESULTS.md."""

PROFILES: Dict[str, Dict[str, Any]] = {"quick": {}, "evidence": EVIDENCE}
"""``dv2s loop --profile NAME``: the values each profile sets (``quick``: the embedded defaults as they are)."""

DEFAULT_PROFILE = "quick"
"""The profile of ``dv2s loop`` without ``--profile``."""
