"""Power of the gate: how many episodes a run needs, and what a run could detect.

The gate tests every scenario on its own (:mod:`dv2s_gym.regress.family`), so the episodes per
scenario decide what a regression confined to one scenario must amount to before the gate sees it.
:func:`plan_episodes` chooses the episodes per scenario before a run, from a minimum detectable
effect (``mde``: an increase of one scenario's failure rate, in points) and a power; every report
states, per scenario and pooled, the power it had at the margin and at the ``mde`` and the smallest
increase it detected with the planned power (:func:`run_power`).

Model (stated in every report): a scenario's baseline failure rate ``p0`` comes from the baseline
report when there is one (its observed rate, with half a failure added so that a clean scenario
is not planned as if it could never fail), else from the baseline policy's episodes of the run,
else :data:`ASSUMED_BASELINE_RATE`. The candidate fails ``p0 + delta`` of the time, with failures
clustering on the same scenes as the baseline's by the shared-difficulty model of
:mod:`dv2s_gym.regress.stats` (latent correlation :data:`~dv2s_gym.regress.stats.DEFAULT_CORRELATION`),
which gives the probability of a discordant pair. Power is then exact: the discordant count is
binomial, and given it the candidate-only count is binomial; the test is the one-sided exact McNemar
test at the level the family gives a scenario when *every* scenario could reach it (``alpha`` times
the scenarios' share over the number of scenarios), so the planned power is a lower bound: Tarone's
refinement gives a lone regressed scenario more.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Optional

import numpy as np
from scipy import stats

from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.family import DEFAULT_POOLED_WEIGHT
from dv2s_gym.regress.records import PowerEstimate, PowerPlan, RunPower, ScenarioPlan
from dv2s_gym.regress.stats import DEFAULT_CORRELATION

__all__ = ["ASSUMED_BASELINE_RATE", "DEFAULT_MDE", "DEFAULT_POWER", "MAX_PLANNED_EPISODES",
           "discordance", "mcnemar_power", "plan_episodes", "run_power", "scenario_level", "smallest_detectable"]

DEFAULT_MDE = 0.30
"""Default minimum detectable effect: one scenario's failure rate up by 30 points."""

DEFAULT_POWER = 0.8
"""Default power to FAIL a regression of the minimum detectable effect."""

ASSUMED_BASELINE_RATE = 0.05
"""Baseline failure rate assumed for planning when no baseline episodes are known."""

MAX_PLANNED_EPISODES = 2000
"""Planning gives up beyond this many episodes per scenario (the effect is too small to detect)."""


def scenario_level(alpha: float, scenarios: int, pooled_weight: float = DEFAULT_POOLED_WEIGHT) -> float:
    """The level a scenario is tested at when every scenario could reach it: ``alpha (1 - w) / K``."""
    return alpha * (1.0 - pooled_weight) / max(1, int(scenarios))


def discordance(p_baseline: float, delta: float) -> float:
    """Probability of a discordant pair when the candidate fails ``delta`` more often (shared-difficulty model).

    ``p_baseline`` is clipped so that both rates lie strictly inside ``(0, 1)``; a rate of 0 becomes a
    tiny one (the candidate's failures are then nearly all discordant, ``psi ~ delta``).
    """
    return _discordance(round(float(p_baseline), 6), round(float(delta), 6))


_NODES, _WEIGHTS = np.polynomial.hermite_e.hermegauss(160)  # E[f(D)], D ~ N(0, 1)
_WEIGHTS = _WEIGHTS / _WEIGHTS.sum()


@functools.lru_cache(maxsize=4096)
def _discordance(p_baseline: float, delta: float) -> float:
    low = 1e-4
    p0 = min(max(p_baseline, low), 1.0 - delta - low)
    if p0 <= 0 or delta <= 0:
        return max(delta, 0.0)
    shared, own = math.sqrt(DEFAULT_CORRELATION), math.sqrt(1.0 - DEFAULT_CORRELATION)
    t0, t1 = stats.norm.isf(p0), stats.norm.isf(p0 + delta)
    both = float(np.sum(_WEIGHTS * stats.norm.sf((t0 - shared * _NODES) / own)
                        * stats.norm.sf((t1 - shared * _NODES) / own)))
    return max(delta, p0 + (p0 + delta) - 2.0 * both)


@functools.lru_cache(maxsize=256)
def _critical_counts_upto(m_max: int, level: float) -> np.ndarray:
    m = np.arange(m_max + 1)
    crit = np.where(m > 0, stats.binom.isf(level, np.maximum(m, 1), 0.5) + 1, 1).astype(np.int64)
    # guard the floating-point edge: step until the tail is at most the level, and no further
    tail = lambda b: np.where(b <= m, stats.binom.sf(b - 1, np.maximum(m, 1), 0.5), 0.0)  # noqa: E731
    crit = np.where((tail(crit) > level) & (crit <= m), crit + 1, crit)
    crit = np.where((crit > 1) & (tail(crit - 1) <= level) & (m > 0), crit - 1, crit)
    return np.minimum(crit, m + 1)


def _critical_counts(m_max: int, level: float) -> np.ndarray:
    """``crit[m]``: smallest candidate-only count whose one-sided exact p-value is at most ``level``
    (``m + 1`` when none is), for ``m`` discordant pairs, ``m = 0..m_max``."""
    size = 1 << max(6, int(m_max).bit_length())  # cached in powers of two
    return _critical_counts_upto(size, float(level))[:m_max + 1]


def mcnemar_power(n: int, psi: float, delta: float, level: float) -> float:
    """Exact power of the one-sided exact McNemar test at ``level`` with ``n`` pairs.

    Args:
        n: paired episodes.
        psi: probability of a discordant pair (at least ``delta``).
        delta: candidate-only minus baseline-only probability (the failure-rate increase).
        level: the test's level.
    """
    n = int(n)
    if n <= 0 or delta <= 0 or psi <= 0:
        return 0.0
    psi = min(1.0, max(float(psi), float(delta)))
    share = min(1.0, (psi + delta) / (2.0 * psi))  # P(candidate-only | discordant)
    m = np.arange(n + 1)
    crit = _critical_counts(n, float(level))
    reach = stats.binom.sf(crit - 1, m, share)
    reach[crit > m] = 0.0
    return float(np.sum(stats.binom.pmf(m, n, psi) * reach))


def _smallest_n(p0: float, delta: float, power: float, level: float) -> Optional[int]:
    psi = discordance(p0, delta)
    low, high = 1, 8
    while mcnemar_power(high, psi, delta, level) < power:
        low, high = high, high * 2
        if high > MAX_PLANNED_EPISODES:
            return None
    while high - low > 1:  # power grows with n up to the discreteness of the exact test
        middle = (low + high) // 2
        if mcnemar_power(middle, psi, delta, level) >= power:
            high = middle
        else:
            low = middle
    while mcnemar_power(high, psi, delta, level) < power:
        high += 1
    return high


def _baseline_rate(rates: Optional[Mapping[str, Optional[float]]], name: str) -> tuple[float, str]:
    value = (rates or {}).get(name)
    if value is None:
        return ASSUMED_BASELINE_RATE, "assumed"
    return float(value), "measured"


def plan_episodes(scenarios: Sequence[str], *, mde: float = DEFAULT_MDE, power: float = DEFAULT_POWER,
                  alpha: float = 0.05, baseline_rates: Optional[Mapping[str, Optional[float]]] = None,
                  pooled_weight: float = DEFAULT_POOLED_WEIGHT) -> PowerPlan:
    """Episodes per scenario so that any one scenario regressing by ``mde`` is FAIL with ``power``.

    Args:
        scenarios: the run's scenario names.
        mde: increase of one scenario's failure rate to detect, in ``(0, 1)``.
        power: probability of FAIL at that increase, in ``(0, 1)``.
        alpha: the gate's family-wise level.
        baseline_rates: baseline failure rate per scenario (planning value, see the module docstring);
            missing or None: :data:`ASSUMED_BASELINE_RATE`.
        pooled_weight: the pooled test's share of ``alpha``.

    Returns:
        The :class:`~dv2s_gym.regress.records.PowerPlan`: ``episodes`` (the most any scenario needs), ``mde``,
        ``power``, ``level``, ``per_scenario`` (a :class:`~dv2s_gym.regress.records.ScenarioPlan` each) and
        ``assumption``.

    Raises:
        RegressError: (a ValueError) when ``mde`` or ``power`` is out of range, or no run of at most
            :data:`MAX_PLANNED_EPISODES` episodes per scenario reaches the power.
    """
    if not 0.0 < float(mde) < 1.0:
        raise RegressError(f"--mde is an increase of one scenario's failure rate in (0, 1), e.g. 0.3 for 30 points; "
                         f"not {mde}")
    if not 0.0 < float(power) < 1.0:
        raise RegressError(f"--power must be strictly between 0 and 1, e.g. 0.8; not {power}")
    level = scenario_level(alpha, len(scenarios), pooled_weight)
    per: dict[str, ScenarioPlan] = {}
    for name in scenarios:
        p0, source = _baseline_rate(baseline_rates, name)
        p0 = min(p0, 1.0 - mde - 1e-4)
        n = _smallest_n(p0, mde, power, level)
        if n is None:
            raise RegressError(f"no run of up to {MAX_PLANNED_EPISODES} episodes per scenario detects a {100 * mde:g}-point "
                             f"regression in {name} with power {power:g}; give a larger --mde or a lower --power")
        per[name] = ScenarioPlan(baseline_rate=p0, source=source, discordance=discordance(p0, mde), episodes=n)
    return PowerPlan(episodes=max(v.episodes for v in per.values()), mde=float(mde), power=float(power), level=level,
                     per_scenario=per, assumption=_assumption({name: v.source for name, v in per.items()}))


def _assumption(sources_by_name: Mapping[str, str]) -> str:
    """The model's assumptions, from each scenario's rate source (``"measured"`` or ``"assumed"``)."""
    sources = set(sources_by_name.values())
    if sources == {"assumed"}:
        rates = f"an assumed baseline failure rate of {100 * ASSUMED_BASELINE_RATE:g}% in every scenario"
    elif sources == {"measured"}:
        rates = "the baseline's measured failure rate per scenario"
    else:
        rates = (f"the baseline's measured failure rate per scenario ({100 * ASSUMED_BASELINE_RATE:g}% assumed "
                 "where none was measured)")
    return (f"{rates}; failures shared with the baseline by a latent correlation of {DEFAULT_CORRELATION:g}; "
            "one-sided exact McNemar test at the level a scenario gets when every scenario could reach it")


def smallest_detectable(n: int, p0: float, power: float, level: float, step: float = 0.005) -> Optional[float]:
    """The smallest increase (a multiple of ``step``) detected with ``power`` by ``n`` pairs, or None if none is.

    Bisection on the grid, assuming power grows with the increase."""
    def reached(k: int) -> bool:
        delta = k * step
        return mcnemar_power(n, discordance(p0, delta), delta, level) >= power

    high = int((1.0 - p0) / step) - 1
    if high < 1 or not reached(high):
        return None
    low = 0  # not reached at 0
    while high - low > 1:
        middle = (low + high) // 2
        if reached(middle):
            high = middle
        else:
            low = middle
    return round(high * step, 6)


def _power_entry(n: int, p0: float, level: float, margin: float, mde: Optional[float], power: float
                 ) -> PowerEstimate:
    def at(delta: float) -> Optional[float]:
        if delta <= 0 or p0 + delta >= 1.0:
            return None
        return mcnemar_power(n, discordance(p0, delta), delta, level)

    return PowerEstimate(n=int(n), baseline_rate=p0, level=level, at_margin=at(margin),
                         at_mde=None if mde is None else at(mde), detectable=smallest_detectable(n, p0, power, level))


def run_power(pairs: Mapping[str, int], baseline_rates: Mapping[str, Optional[float]], *, margin: float,
              alpha: float, mde: Optional[float] = DEFAULT_MDE, power: float = DEFAULT_POWER,
              pooled_weight: float = DEFAULT_POOLED_WEIGHT) -> RunPower:
    """The power a run had, per scenario and pooled, under the model of the module docstring.

    Args:
        pairs: paired episodes per scenario (without errors).
        baseline_rates: the baseline's observed failure rate per scenario (None: unknown, assumed).
        margin: the non-inferiority margin (power "at the margin": to FAIL an increase of ``margin``).
        alpha: the gate's family-wise level.
        mde: the minimum detectable effect the run was planned for (power at it per scenario).
        power: the planned power (``detectable``: the smallest increase detected with it).
        pooled_weight: the pooled test's share of ``alpha``.

    Returns:
        The :class:`~dv2s_gym.regress.records.RunPower`: a :class:`~dv2s_gym.regress.records.PowerEstimate` per
        scenario (``per_scenario``) and ``pooled``, the ``power``, the ``mde`` and the ``assumption``.
    """
    names = list(pairs)
    level = scenario_level(alpha, len(names), pooled_weight)
    per: dict[str, PowerEstimate] = {}
    planning: dict[str, str] = {}
    for name in names:
        p0, source = _baseline_rate(baseline_rates, name)
        planning[name] = source
        per[name] = _power_entry(pairs[name], _planning_rate(p0, pairs[name], source), level, margin, mde, power)
    total = sum(int(v) for v in pairs.values())
    known = [(pairs[n], baseline_rates.get(n)) for n in names if baseline_rates.get(n) is not None]
    if known and sum(k for k, _ in known):
        pooled_rate = sum(k * r for k, r in known) / sum(k for k, _ in known)
        pooled_source = "measured"
    else:
        pooled_rate, pooled_source = ASSUMED_BASELINE_RATE, "assumed"
    pooled = _power_entry(total, _planning_rate(pooled_rate, total, pooled_source), alpha * pooled_weight, margin,
                          None, power)
    return RunPower(per_scenario=per, pooled=pooled, power=float(power), mde=mde, assumption=_assumption(planning))


def _planning_rate(rate: float, n: int, source: str) -> float:
    """A measured rate with half a failure added (a clean scenario can still fail); an assumed one as is."""
    if source != "measured" or n <= 0:
        return float(rate)
    return (float(rate) * n + 0.5) / (n + 1)
