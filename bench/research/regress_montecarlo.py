"""The paired-outcome model of ``dv2s regress``'s statistics, sample-size formulas and Monte Carlo of its rules.

Research code for ``bench/calibrate_regress.py`` and ``bench/tests/``: ``dv2s regress`` itself plans runs with
:mod:`dv2s_gym.regress.power` and decides with :mod:`dv2s_gym.regress.stats` and :mod:`dv2s_gym.regress.family`;
this module measures how those decisions behave on synthetic paired outcomes.

Power and the paired-outcome model
----------------------------------
:func:`paired_sample_size` is Connor's (1987) normal approximation for McNemar's test,
:func:`unpaired_sample_size` the usual two-proportion one (Fleiss, without continuity
correction), both one-sided. The simulations (:func:`simulate_power`,
:func:`simulate_false_alarm`) draw paired episodes from a shared-difficulty model: every episode
(scene) has a latent difficulty ``D ~ N(0, 1)``, shared by both policies, and policy ``j`` fails
when ``sqrt(rho) * D + sqrt(1 - rho) * E_j > Phi^-1(1 - p_j)`` with its own noise
``E_j ~ N(0, 1)``. Each policy keeps its failure rate ``p_j``; ``rho`` (the latent, tetrachoric
correlation) makes failures cluster on the same scenes. The default ``rho = 0.5``
(:data:`~dv2s_gym.regress.stats.DEFAULT_CORRELATION`, the one power planning
uses) is a moderate choice: at 5 % vs 8 % failure rates it gives a phi
correlation of about 0.22 between the paired outcomes and 9.6 % discordant pairs (12.2 % for
independent policies). :data:`DOCUMENTED_EPISODES` paired episodes give at least 80 % power to
FAIL a candidate at 8 % against a 5 % baseline under that model.
:func:`verdicts_of_tables` is :func:`~dv2s_gym.regress.stats.compare`'s rule vectorised over many tables.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import integrate, stats

from policies.stats import check_level, two_sided_z
from dv2s_gym.regress.stats import (
    _VERDICT_OF_CODE,
    DEFAULT_ALPHA,
    DEFAULT_CORRELATION,
    DEFAULT_MARGIN,
    Verdict,
    _decide,
    _mcnemar_greater,
    _newcombe_bounds,
    wilson_interval,
)

DOCUMENTED_BASELINE_RATE = 0.05
"""Baseline failure rate of the documented power target."""

DOCUMENTED_DELTA = 0.03
"""Increase in the failure rate the documented episode count detects (+3 percentage points)."""

DOCUMENTED_POWER = 0.8
"""Power the documented episode count reaches."""

DOCUMENTED_EPISODES = 800
"""Paired episodes per policy for 80 % power to FAIL +3 pp from a 5 % baseline (rho = 0.5).

Connor's normal approximation gives 661; the exact McNemar test is conservative, and by
simulation :func:`compare` needs about 720 (740 in a smaller run); at 800 its power is 0.85 (Monte
Carlo, 4000 runs), a margin that keeps the calibration test off its bound whatever the seed.
Unpaired, the same detection needs 834 (normal) or about 890 (Fisher exact) episodes per policy.
See ``bench/RESULTS.md``.
"""


def _check_rates(p_baseline: float, p_candidate: float) -> None:
    for name, value in (("p_baseline", p_baseline), ("p_candidate", p_candidate)):
        if not 0.0 < value < 1.0:
            raise ValueError(f"{name} must be strictly between 0 and 1, got {value}")


def _check_correlation(correlation: float) -> float:
    correlation = float(correlation)
    if not 0.0 <= correlation <= 1.0:
        raise ValueError(f"correlation (latent, shared difficulty) must be in [0, 1], got {correlation}")
    return correlation


def paired_cell_probabilities(
    p_baseline: float, p_candidate: float, correlation: float = DEFAULT_CORRELATION
) -> tuple[float, float, float, float]:
    """Cell probabilities of the paired table under the shared-difficulty model.

    Policy ``j`` fails when ``sqrt(rho) D + sqrt(1 - rho) E_j > Phi^-1(1 - p_j)``, with the
    scene's difficulty ``D`` shared and ``D, E_1, E_2`` independent standard normals. The
    probability that both fail is integrated over ``D``.

    Args:
        p_baseline: Baseline failure rate.
        p_candidate: Candidate failure rate.
        correlation: Latent correlation ``rho`` in ``[0, 1]``.

    Returns:
        ``(both_fail, candidate_only, baseline_only, neither)`` probabilities.
    """
    _check_rates(p_baseline, p_candidate)
    rho = _check_correlation(correlation)
    if rho == 0.0:
        both = p_baseline * p_candidate
    elif rho == 1.0:
        both = min(p_baseline, p_candidate)
    else:
        shared, own = math.sqrt(rho), math.sqrt(1.0 - rho)
        t_base, t_cand = stats.norm.isf(p_baseline), stats.norm.isf(p_candidate)

        def integrand(difficulty: float) -> float:
            return float(stats.norm.pdf(difficulty)
                         * stats.norm.sf((t_base - shared * difficulty) / own)
                         * stats.norm.sf((t_cand - shared * difficulty) / own))

        both = integrate.quad(integrand, -np.inf, np.inf, epsabs=1e-12, epsrel=1e-10)[0]
    return both, p_candidate - both, p_baseline - both, 1.0 - p_baseline - p_candidate + both


def discordant_probability(
    p_baseline: float, p_candidate: float, correlation: float = DEFAULT_CORRELATION
) -> float:
    """Probability that exactly one policy fails an episode, under the shared-difficulty model."""
    _, candidate_only, baseline_only, _ = paired_cell_probabilities(p_baseline, p_candidate, correlation)
    return candidate_only + baseline_only


def _check_design(p_baseline: float, delta: float, alpha: float, power: float) -> tuple[float, float]:
    _check_rates(p_baseline, p_baseline + delta)
    if delta <= 0:
        raise ValueError(f"delta (the increase in failure rate to detect) must be positive, got {delta}")
    return float(stats.norm.isf(check_level(alpha, "alpha"))), float(stats.norm.ppf(check_level(power, "power")))


def paired_sample_size(
    p_baseline: float,
    delta: float,
    alpha: float = DEFAULT_ALPHA,
    power: float = DOCUMENTED_POWER,
    discordance: float | None = None,
    correlation: float | None = None,
) -> int:
    """Paired episodes (per policy) for a one-sided McNemar test, Connor's (1987) formula.

    ``n = (z_{1-alpha} sqrt(psi) + z_{power} sqrt(psi - delta^2))^2 / delta^2``, with ``psi`` the
    probability of a discordant pair. Give ``psi`` directly as ``discordance``, or a latent
    ``correlation`` for the shared-difficulty model (default :data:`DEFAULT_CORRELATION`).

    Args:
        p_baseline: Baseline failure rate.
        delta: Increase of the candidate's failure rate to detect.
        alpha: One-sided level.
        power: Power to reach.
        discordance: Probability of a discordant pair (at least ``delta``).
        correlation: Latent correlation of the shared-difficulty model (if no discordance).

    Returns:
        Episodes needed, rounded up.
    """
    z_alpha, z_power = _check_design(p_baseline, delta, alpha, power)
    if discordance is not None and correlation is not None:
        raise ValueError("give either discordance or correlation, not both")
    if discordance is None:
        rho = DEFAULT_CORRELATION if correlation is None else correlation
        psi = discordant_probability(p_baseline, p_baseline + delta, rho)
    else:
        psi = float(discordance)
    if not delta <= psi <= 1.0:
        raise ValueError(f"discordance must lie between delta={delta} and 1, got {psi}")
    n = (z_alpha * math.sqrt(psi) + z_power * math.sqrt(psi - delta**2)) ** 2 / delta**2
    return math.ceil(n - 1e-9)


def unpaired_sample_size(
    p_baseline: float, delta: float, alpha: float = DEFAULT_ALPHA, power: float = DOCUMENTED_POWER
) -> int:
    """Episodes per policy for a one-sided test of two independent proportions.

    ``n = (z_{1-alpha} sqrt(2 pbar qbar) + z_{power} sqrt(p1 q1 + p2 q2))^2 / delta^2``
    (normal approximation, pooled variance under H0, no continuity correction), i.e. what the
    same detection needs when the two policies run on different scenes.

    Args:
        p_baseline: Baseline failure rate.
        delta: Increase of the candidate's failure rate to detect.
        alpha: One-sided level.
        power: Power to reach.

    Returns:
        Episodes per policy, rounded up.
    """
    z_alpha, z_power = _check_design(p_baseline, delta, alpha, power)
    p1, p2 = p_baseline, p_baseline + delta
    mean = (p1 + p2) / 2.0
    n = (z_alpha * math.sqrt(2.0 * mean * (1.0 - mean))
         + z_power * math.sqrt(p1 * (1.0 - p1) + p2 * (1.0 - p2))) ** 2 / delta**2
    return math.ceil(n - 1e-9)


def simulate_paired_outcomes(
    n_episodes: int,
    p_baseline: float,
    p_candidate: float,
    correlation: float = DEFAULT_CORRELATION,
    repetitions: int = 1,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Draw paired episode outcomes from the shared-difficulty model.

    Args:
        n_episodes: Paired episodes per repetition.
        p_baseline: Baseline failure rate.
        p_candidate: Candidate failure rate.
        correlation: Latent correlation ``rho`` (shared difficulty of the scene).
        repetitions: Independent runs to draw.
        rng: numpy Generator (a fresh unseeded one if None).

    Returns:
        ``(candidate_failed, baseline_failed)``, boolean arrays of shape
        ``(repetitions, n_episodes)``, paired along the last axis.
    """
    _check_rates(p_baseline, p_candidate)
    rho = _check_correlation(correlation)
    rng = np.random.default_rng() if rng is None else rng
    shape = (repetitions, n_episodes)
    difficulty = rng.standard_normal(shape)
    shared, own = math.sqrt(rho), math.sqrt(1.0 - rho)
    candidate = shared * difficulty + own * rng.standard_normal(shape) > stats.norm.isf(p_candidate)
    baseline = shared * difficulty + own * rng.standard_normal(shape) > stats.norm.isf(p_baseline)
    return candidate, baseline


def simulate_tables(
    n_episodes: int,
    p_baseline: float,
    p_candidate: float,
    correlation: float = DEFAULT_CORRELATION,
    repetitions: int = 1,
    rng: np.random.Generator | None = None,
    chunk: int = 500,
) -> np.ndarray:
    """Paired tables of simulated runs (episodes drawn by :func:`simulate_paired_outcomes`).

    Returns:
        Integer array ``(repetitions, 4)``: both_fail, candidate_only, baseline_only, neither.
    """
    rng = np.random.default_rng() if rng is None else rng
    tables = np.empty((repetitions, 4), dtype=np.int64)
    for start in range(0, repetitions, chunk):
        size = min(chunk, repetitions - start)
        cand, base = simulate_paired_outcomes(n_episodes, p_baseline, p_candidate, correlation, size, rng)
        tables[start:start + size] = np.stack(
            [(cand & base).sum(1), (cand & ~base).sum(1), (~cand & base).sum(1), (~cand & ~base).sum(1)],
            axis=1,
        )
    return tables


def verdicts_of_tables(tables: np.ndarray, margin: float, alpha: float = DEFAULT_ALPHA) -> list[Verdict]:
    """:func:`compare`'s verdicts for many tables at once (rows of counts, as from :func:`simulate_tables`)."""
    return [_VERDICT_OF_CODE[int(code)] for code in _verdict_codes(np.asarray(tables), margin, alpha)]


def _verdict_codes(tables: np.ndarray, margin: float, alpha: float) -> np.ndarray:
    a, b, c, d = tables.T
    n = tables.sum(axis=1)
    _, upper = _newcombe_bounds(a, b, c, d, two_sided_z(1.0 - alpha))
    difference = (b - c) / np.where(n > 0, n, 1)
    return _decide(upper, difference, _mcnemar_greater(b, c), margin, alpha)


@dataclass(frozen=True)
class MonteCarloRate:
    """How often an event happened in simulated runs.

    Attributes:
        count: Runs where it happened.
        repetitions: Runs simulated.
    """

    count: int
    repetitions: int

    @property
    def rate(self) -> float:
        """Observed rate."""
        return self.count / self.repetitions

    def interval(self, confidence: float = 0.95) -> tuple[float, float]:
        """Wilson interval of the rate."""
        return wilson_interval(self.count, self.repetitions, confidence)

    def __float__(self) -> float:
        return self.rate

    def __str__(self) -> str:
        low, high = self.interval()
        return f"{self.rate:.4f} (95% CI {low:.4f}-{high:.4f}, {self.count}/{self.repetitions})"


def simulate_verdict_rates(
    n_episodes: int,
    p_baseline: float,
    p_candidate: float,
    margin: float = DEFAULT_MARGIN,
    alpha: float = DEFAULT_ALPHA,
    correlation: float = DEFAULT_CORRELATION,
    repetitions: int = 2000,
    rng: np.random.Generator | None = None,
) -> dict[Verdict, MonteCarloRate]:
    """How often :func:`compare` says PASS, FAIL and INCONCLUSIVE on simulated paired runs.

    Each repetition draws ``n_episodes`` paired episodes from the shared-difficulty model
    (:func:`simulate_paired_outcomes`) and applies the decision rule to their table.

    Returns:
        A :class:`MonteCarloRate` per verdict.
    """
    tables = simulate_tables(n_episodes, p_baseline, p_candidate, correlation, repetitions, rng)
    codes = _verdict_codes(tables, margin, check_level(alpha, "alpha"))
    return {verdict: MonteCarloRate(int(np.sum(codes == code)), repetitions)
            for code, verdict in _VERDICT_OF_CODE.items()}


def simulate_power(
    n_episodes: int = DOCUMENTED_EPISODES,
    p_baseline: float = DOCUMENTED_BASELINE_RATE,
    delta: float = DOCUMENTED_DELTA,
    margin: float = DEFAULT_MARGIN,
    alpha: float = DEFAULT_ALPHA,
    correlation: float = DEFAULT_CORRELATION,
    repetitions: int = 2000,
    rng: np.random.Generator | None = None,
) -> MonteCarloRate:
    """Rate of FAIL verdicts when the candidate fails ``delta`` more often than the baseline."""
    return simulate_verdict_rates(n_episodes, p_baseline, p_baseline + delta, margin, alpha, correlation,
                                  repetitions, rng)[Verdict.FAIL]


def simulate_false_alarm(
    n_episodes: int = DOCUMENTED_EPISODES,
    p_baseline: float = DOCUMENTED_BASELINE_RATE,
    margin: float = DEFAULT_MARGIN,
    alpha: float = DEFAULT_ALPHA,
    correlation: float = DEFAULT_CORRELATION,
    repetitions: int = 2000,
    rng: np.random.Generator | None = None,
) -> MonteCarloRate:
    """Rate of FAIL verdicts when both policies have the same failure rate (a false alarm)."""
    return simulate_verdict_rates(n_episodes, p_baseline, p_baseline, margin, alpha, correlation,
                                  repetitions, rng)[Verdict.FAIL]


def simulate_unpaired_power(
    n_episodes: int,
    p_baseline: float = DOCUMENTED_BASELINE_RATE,
    delta: float = DOCUMENTED_DELTA,
    alpha: float = DEFAULT_ALPHA,
    repetitions: int = 2000,
    rng: np.random.Generator | None = None,
) -> MonteCarloRate:
    """Power of the unpaired counterpart: each policy on its own ``n_episodes`` scenes.

    The failure counts are independent binomials, tested by the one-sided Fisher exact test
    (the unpaired exact analogue of the exact McNemar test).
    """
    _check_rates(p_baseline, p_baseline + delta)
    rng = np.random.default_rng() if rng is None else rng
    candidate = rng.binomial(n_episodes, p_baseline + delta, repetitions)
    baseline = rng.binomial(n_episodes, p_baseline, repetitions)
    # P(candidate failures >= observed | total failures), hypergeometric under H0
    p_value = stats.hypergeom.sf(candidate - 1, 2 * n_episodes, candidate + baseline, n_episodes)
    detected = (p_value < alpha) & (candidate > baseline)
    return MonteCarloRate(int(detected.sum()), repetitions)


def simulated_sample_size(
    p_baseline: float = DOCUMENTED_BASELINE_RATE,
    delta: float = DOCUMENTED_DELTA,
    alpha: float = DEFAULT_ALPHA,
    power: float = DOCUMENTED_POWER,
    correlation: float | None = DEFAULT_CORRELATION,
    margin: float = DEFAULT_MARGIN,
    repetitions: int = 2000,
    step: int = 10,
    seed: int = 0,
) -> int:
    """Smallest episode count (a multiple of ``step``) whose simulated power reaches ``power``.

    Bisection between half and twice the analytic size, assuming power grows with the
    episode count; every candidate count is simulated with the same seed (common random
    numbers), so the answer moves by about ``step`` from seed to seed, more when the power
    curve is flat. Paired (``correlation`` given): FAIL rate of :func:`compare` under the
    shared-difficulty model. Unpaired (``correlation=None``): one-sided Fisher exact test on
    independent samples (:func:`simulate_unpaired_power`).
    """
    def reached(n: int) -> bool:
        rng = np.random.default_rng(seed)
        if correlation is None:
            rate = simulate_unpaired_power(n, p_baseline, delta, alpha, repetitions, rng)
        else:
            rate = simulate_power(n, p_baseline, delta, margin, alpha, correlation, repetitions, rng)
        return rate.rate >= power

    if correlation is None:
        analytic = unpaired_sample_size(p_baseline, delta, alpha, power)
    else:
        analytic = paired_sample_size(p_baseline, delta, alpha, power, correlation=correlation)
    # in units of step; invariant: power not reached at low (0 episodes: never), reached at high
    low, high = analytic // (2 * step), -(-2 * analytic // step)
    if low > 0 and reached(low * step):
        low = 0
    while not reached(high * step):
        low, high = high, high * 2
    while high - low > 1:
        middle = (low + high) // 2
        if reached(middle * step):
            high = middle
        else:
            low = middle
    return high * step
