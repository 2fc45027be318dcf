"""The statistics primitives the model card and the regression gate share: the Wilson score interval of a
binomial proportion and the exact McNemar test of paired outcomes.

A model card (:mod:`policies.model_card`) reports its rates with Wilson intervals and compares a policy with
its baselines by exact McNemar tests; ``dv2s regress`` (:mod:`dv2s_gym.regress.stats`), the failure miner and
the closed loop build their verdicts on the same two computations, so they live here, in the lowest layer that
needs them, once.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass, field
from typing import Any, ClassVar, FrozenSet, Mapping, Optional, Tuple

import numpy as np

from envs.errors import DV2SError
from scenario_bank.records import JsonRecord

__all__ = ["StatisticsError", "ALTERNATIVES", "check_level", "check_count", "two_sided_z", "wilson_bounds",
           "wilson_interval", "mcnemar_p", "Rate"]

ALTERNATIVES = ("two-sided", "greater", "less")
"""The alternatives of :func:`mcnemar_p`."""


class StatisticsError(DV2SError, ValueError):
    """A statistic asked for with arguments outside its domain (a level not strictly between 0 and 1, counts
    that are negative or exceed their total, an unknown alternative); the message names the argument."""


def check_level(value: float, name: str) -> float:
    """``value`` as a float, checked to lie strictly between 0 and 1 (a confidence level, an ``alpha``);
    :class:`StatisticsError` names ``name`` otherwise."""
    value = float(value)
    if not 0.0 < value < 1.0:
        raise StatisticsError(f"{name} must be strictly between 0 and 1, got {value}")
    return value


def check_count(k: int, n: int) -> Tuple[int, int]:
    """``(k, n)`` as integers with ``0 <= k <= n`` (a :class:`TypeError` for a non-integer)."""
    k, n = operator.index(k), operator.index(n)
    if n < 0 or not 0 <= k <= n:
        raise StatisticsError(f"need 0 <= k <= n, got k={k}, n={n}")
    return k, n


def two_sided_z(confidence: float) -> float:
    """Normal quantile for a two-sided interval of the given confidence."""
    from scipy import stats  # slow to import: the records of this module are read at the command line's start

    return float(stats.norm.ppf(0.5 + check_level(confidence, "confidence") / 2.0))


def wilson_bounds(k: np.ndarray, n: np.ndarray, z: float) -> Tuple[np.ndarray, np.ndarray]:
    """Vectorised Wilson score bounds of ``k`` successes in ``n`` trials at normal quantile ``z``;
    ``(0, 1)`` where ``n == 0``."""
    k = np.asarray(k, dtype=float)
    n = np.asarray(n, dtype=float)
    size = np.where(n > 0, n, 1.0)
    p = k / size
    z2 = z * z
    denominator = 1.0 + z2 / size
    centre = (p + z2 / (2.0 * size)) / denominator
    half = z * np.sqrt(np.maximum(p * (1.0 - p), 0.0) / size + z2 / (4.0 * size * size)) / denominator
    low = np.where((n > 0) & (k > 0), np.clip(centre - half, 0.0, 1.0), 0.0)
    high = np.where((n > 0) & (k < n), np.clip(centre + half, 0.0, 1.0), 1.0)
    return low, high


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> Tuple[float, float]:
    """Wilson score interval for a binomial proportion.

    Args:
        k: Number of successes (a failed episode, a collision, ...).
        n: Number of trials.
        confidence: Two-sided confidence level.

    Returns:
        ``(low, high)``; ``(0.0, 1.0)`` when ``n == 0``.
    """
    k, n = check_count(k, n)
    low, high = wilson_bounds(np.array(k), np.array(n), two_sided_z(confidence))
    return float(low), float(high)


@dataclass(frozen=True, eq=False)
class Rate(JsonRecord):
    """A rate of events: ``k`` of ``n`` episodes, the ``rate`` (``None`` without an episode) and its Wilson
    interval ``low``..``high`` (:meth:`of`). Its JSON object is ``{"k", "n", "rate", "low", "high"}``, every key
    written (``null`` when ``None``); a file that names the bounds otherwise writes its own object from the
    fields."""

    k: Optional[int] = None
    n: Optional[int] = None
    rate: Optional[float] = None
    low: Optional[float] = None
    high: Optional[float] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "rate"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()

    @classmethod
    def of(cls, k: int, n: int, confidence: float = 0.95) -> "Rate":
        """``k`` events in ``n`` episodes with the two-sided Wilson interval at ``confidence``
        (:func:`wilson_interval`; ``rate`` ``None`` when ``n`` is 0)."""
        low, high = wilson_interval(int(k), int(n), confidence)
        return cls(k=int(k), n=int(n), rate=(k / n) if n else None, low=low, high=high)

    def report_json(self, scale: float = 1.0, with_n: bool = False) -> Dict[str, Any]:
        """The rate as the mining and regression reports write it: ``{"value", "low", "high", "count"}`` (and
        ``"n"`` with ``with_n``), the value and its bounds times ``scale`` (``100.0``: per 100 episodes); ``null``
        value and bounds without an episode."""
        count, n = int(self.k or 0), int(self.n or 0)
        if n == 0:
            data: Dict[str, Any] = {"value": None, "low": None, "high": None, "count": count}
        else:
            data = {"value": scale * count / n, "low": scale * self.low, "high": scale * self.high, "count": count}
        return {**data, "n": n} if with_n else data

    def text(self, digits: int = 2, counts: bool = True) -> str:
        """The rate as ``k/n = rate [low, high]`` (without ``counts``: ``rate [low, high]``), ``digits`` decimals;
        ``-`` without a rate."""
        if self.rate is None:
            return "-"
        shown = f"{self.rate:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"
        return f"{self.k}/{self.n} = {shown}" if counts else shown


def mcnemar_p(candidate_only: int, baseline_only: int, alternative: str = "two-sided") -> float:
    """Exact McNemar p-value of paired outcomes: a binomial test of the discordant pairs.

    Given ``m = candidate_only + baseline_only`` discordant pairs (the candidate had the event and the
    baseline did not, or the other way round), ``candidate_only`` is Binomial(m, 1/2) when the two have the
    event alike.

    Args:
        candidate_only: Pairs where only the candidate had the event.
        baseline_only: Pairs where only the baseline had it.
        alternative: ``"two-sided"``; ``"greater"`` (the candidate has the event more often); or ``"less"``.

    Returns:
        The p-value; 1.0 when there are no discordant pairs.
    """
    if alternative not in ALTERNATIVES:
        raise StatisticsError(f"alternative must be 'two-sided', 'greater' or 'less', got {alternative!r}")
    discordant = int(candidate_only) + int(baseline_only)
    if discordant == 0:
        return 1.0
    from scipy import stats

    return float(min(1.0, stats.binomtest(int(candidate_only), discordant, 0.5, alternative=alternative).pvalue))
