"""Statistics of ``dv2s regress``: did the candidate policy get worse than the baseline?

``dv2s regress`` runs a candidate and a baseline policy on the same scenario x seed pairs, so
every episode of the candidate has a twin episode of the baseline on the identical scene. An
episode either fails (crash, off-road, ... as ``dv2s regress`` defines it) or not. This module
turns those paired outcomes into a verdict; it knows nothing about the simulator.

The paired 2x2 table
--------------------
:class:`PairedTable` counts the pairs: ``both_fail``, ``candidate_only`` (the candidate failed,
the baseline did not), ``baseline_only`` and ``neither``. The failure rates are
``(both_fail + candidate_only) / n`` and ``(both_fail + baseline_only) / n``; their difference
(candidate - baseline) is ``(candidate_only - baseline_only) / n``: only the discordant pairs
carry information about it, which is why pairing pays when both policies tend to fail on the
same hard scenes.

Decision rule (:func:`compare`): non-inferiority on the failure rate
-------------------------------------------------------------------
With a margin ``m`` (e.g. 0.02: the candidate may fail at most 2 percentage points more often)
and a level ``alpha`` (default 0.05):

1. **PASS** when the upper end of the two-sided ``1 - alpha`` confidence interval of the
   difference (Newcombe's hybrid score interval, :func:`paired_difference_interval`) is below
   ``m``: the candidate is shown not to be worse by ``m`` or more. This is a one-sided test of
   ``H0: difference >= m`` at level ``alpha / 2`` (the ICH E9 convention for non-inferiority:
   the two-sided 95 % interval), so ``P(PASS) <= alpha / 2`` nominally when the true difference
   equals the margin; the Monte Carlo calibration checks ``P(PASS) <= alpha``.
2. Otherwise **FAIL** when the candidate fails significantly more often: the one-sided exact
   McNemar p-value (:func:`mcnemar_exact`, ``alternative="greater"``) is below ``alpha`` (for the
   tables of a run, the family of tests of :func:`compare_scenarios` decides instead), and the
   difference is positive. The exact conditional test never exceeds its level, so
   ``P(FAIL) <= alpha`` when the two policies fail alike.
3. Otherwise **INCONCLUSIVE**. A run too small to tell is INCONCLUSIVE, never PASS: with 3
   paired episodes and no failure at all, the interval's upper end is about 0.56.

PASS is checked first: a candidate that is significantly worse, but provably by less than the
margin, passes (that is what a non-inferiority margin means).

Scenarios (:func:`compare_scenarios`)
-------------------------------------
Every scenario is a test in its own right: the scenarios' one-sided McNemar tests and the pooled
table's (all scenarios together) form one family, tested by a step-down weighted Bonferroni
procedure with Tarone's refinement for discrete tests (:mod:`dv2s_gym.regress.family`), so the
family-wise false-alarm rate is at most ``alpha`` and a regression confined to one scenario cannot
be averaged away by the others. The pooled test starts with half of ``alpha``
(:data:`~dv2s_gym.regress.family.DEFAULT_POOLED_WEIGHT`), the scenarios share the other half. The overall verdict is FAIL if any scenario FAILs or the pooled
comparison FAILs; PASS if the pooled comparison PASSes, no scenario FAILs and no scenario is
significantly worse *on its own* (its unadjusted one-sided exact McNemar p-value below ``alpha`` with
the candidate failing more: a regression too small for the adjusted test to confirm, but too clear
to wave through); INCONCLUSIVE otherwise, naming those scenarios. The extra PASS condition only
turns PASS into INCONCLUSIVE, so the false-FAIL rate is unchanged. Measured rates: ``bench/RESULTS.md``.

Early stopping (:class:`SequentialTest`)
----------------------------------------
A group-sequential version of the same rule for batches of paired episodes, with the Lan-DeMets
O'Brien-Fleming alpha-spending function over the information fraction ``episodes / max_episodes``
(it spends almost nothing early, so a run that goes to the end keeps the fixed design's power). The FAIL boundary is exact: under "the policies fail alike" the
signs of the discordant pairs are fair coin flips whatever their number, so the boundary at each
look is computed by exact recursion on that coin sequence, conditional on the discordant counts
seen so far, spending ``alpha`` in total. The PASS boundary spends ``alpha / 2`` (the level of
:func:`compare`'s PASS) by Bonferroni over the looks: at a look that is allotted ``a_k`` of it,
PASS needs the upper end of the two-sided ``1 - 2 a_k`` interval below the margin.

``dv2s regress --sequential`` runs it on the pooled table with the pooled test's share of ``alpha``
and without interim PASS (``stop_for_pass=False``): it stops early only for FAIL, and the gate
(:func:`compare_scenarios`, with the pooled member decided by the sequential test) gives the verdict.

The primitives
--------------
The Wilson interval (:func:`wilson_interval`) and the exact McNemar test are :mod:`policies.stats`'s, shared
with the model cards of :mod:`policies.model_card`.

Power
-----
:mod:`dv2s_gym.regress.power` plans a run's episodes and states its power. How these rules behave on
synthetic paired outcomes (false alarms, P(PASS) at the margin, power, sample sizes, paired against
unpaired) is measured by ``bench/calibrate_regress.py`` with the paired-outcome model of
``bench/research/regress_montecarlo.py``; the figures are in ``bench/RESULTS.md``.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from dv2s_gym.regress.family import DEFAULT_POOLED_WEIGHT, gate_rejections
from dv2s_gym.regress.errors import RegressError, SequenceStoppedError
from policies.stats import check_level, mcnemar_p, two_sided_z, wilson_bounds, wilson_interval
from scenario_bank.errors import WrongTypeError

__all__ = ["DEFAULT_ALPHA", "DEFAULT_MARGIN", "DEFAULT_CORRELATION", "Verdict", "wilson_interval",
           "cluster_bootstrap_mean", "PairedTable",
           "paired_difference_interval", "mcnemar_exact", "holm", "weighted_holm", "Comparison", "compare",
           "compare_scenarios", "SPENDING", "obrien_fleming_spending", "Look", "SequentialTest"]

DEFAULT_ALPHA = 0.05
"""Level of the FAIL test (one-sided); PASS is tested at ``alpha / 2``."""

DEFAULT_MARGIN = 0.02
"""Non-inferiority margin on the failure rate: the candidate may fail 2 percentage points more."""


DEFAULT_CORRELATION = 0.5
"""Latent correlation ``rho`` of the shared-difficulty model (a scene's difficulty shared by both policies) that
:mod:`dv2s_gym.regress.power` plans runs with: at 5 % vs 8 % failure rates it gives 9.6 % discordant pairs
(12.2 % for independent policies)."""

_FAIL, _PASS, _INCONCLUSIVE = 0, 1, 2


class Verdict(str, enum.Enum):
    """Outcome of a regression comparison."""

    PASS = "pass"
    FAIL = "fail"
    INCONCLUSIVE = "inconclusive"


_VERDICT_OF_CODE = {_FAIL: Verdict.FAIL, _PASS: Verdict.PASS, _INCONCLUSIVE: Verdict.INCONCLUSIVE}


# ---------------------------------------------------------------------------------------------
# Cluster bootstrap


def cluster_bootstrap_mean(
    groups: Sequence[Sequence[float]],
    confidence: float = 0.95,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Mean of all values with a bootstrap interval that resamples whole groups.

    Episodes of one scenario are not independent (same map, same actors), so the interval
    resamples scenarios (groups) with replacement, keeping each one's values together, and
    recomputes the pooled mean (sum of the drawn groups' values over their total count).
    The interval is the percentile interval of those means. With a single group it collapses
    to the estimate: one scenario says nothing about variation between scenarios.

    Args:
        groups: One sequence of values per group; empty groups are ignored.
        confidence: Two-sided confidence level.
        n_resamples: Number of bootstrap resamples.
        seed: Seed of the numpy Generator, for a reproducible interval.

    Returns:
        ``(estimate, low, high)``.

    Raises:
        RegressError: If there are no values at all (a ValueError).
    """
    tail = (1.0 - check_level(confidence, "confidence")) / 2.0
    sums = np.array([float(np.sum(np.asarray(g, dtype=float))) for g in groups if len(g) > 0])
    sizes = np.array([len(g) for g in groups if len(g) > 0], dtype=float)
    if sizes.size == 0:
        raise RegressError("cluster_bootstrap_mean needs at least one value")
    if n_resamples < 1:
        raise RegressError(f"n_resamples must be positive, got {n_resamples}")
    estimate = float(sums.sum() / sizes.sum())
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, sizes.size, size=(n_resamples, sizes.size))
    means = sums[picks].sum(axis=1) / sizes[picks].sum(axis=1)
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return estimate, float(low), float(high)


# ---------------------------------------------------------------------------------------------
# Paired table


@dataclass(frozen=True)
class PairedTable:
    """Counts of paired episodes (candidate vs baseline on the same scene and seed).

    Attributes:
        both_fail: Pairs where both policies failed.
        candidate_only: Pairs where the candidate failed and the baseline did not.
        baseline_only: Pairs where the baseline failed and the candidate did not.
        neither: Pairs where neither failed.
    """

    both_fail: int = 0
    candidate_only: int = 0
    baseline_only: int = 0
    neither: int = 0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            try:
                count = operator.index(value)
            except TypeError:
                raise WrongTypeError(f"{field.name} must be an integer count, got {value!r}") from None
            if count < 0:
                raise RegressError(f"{field.name} must not be negative, got {count}")
            object.__setattr__(self, field.name, int(count))

    @classmethod
    def from_outcomes(cls, candidate: Sequence[bool], baseline: Sequence[bool]) -> PairedTable:
        """Count paired outcomes; ``True`` means the episode failed.

        Args:
            candidate: The candidate's outcome per episode.
            baseline: The baseline's outcome on the same episodes, paired by index.

        Raises:
            RegressError (a ValueError): If the lengths differ or an outcome is not a boolean (or 0/1).
        """
        if len(candidate) != len(baseline):
            raise RegressError(
                f"paired outcomes need the same length: candidate has {len(candidate)} episodes, "
                f"baseline has {len(baseline)}"
            )
        cand = _as_bool_array(candidate, "candidate")
        base = _as_bool_array(baseline, "baseline")
        return cls(
            both_fail=int(np.sum(cand & base)),
            candidate_only=int(np.sum(cand & ~base)),
            baseline_only=int(np.sum(~cand & base)),
            neither=int(np.sum(~cand & ~base)),
        )

    @classmethod
    def pooled(cls, tables: Sequence[PairedTable]) -> PairedTable:
        """Sum of several tables (e.g. all scenarios)."""
        total = cls()
        for table in tables:
            total = total + table
        return total

    def __add__(self, other: PairedTable) -> PairedTable:
        if not isinstance(other, PairedTable):
            return NotImplemented
        return PairedTable(
            self.both_fail + other.both_fail,
            self.candidate_only + other.candidate_only,
            self.baseline_only + other.baseline_only,
            self.neither + other.neither,
        )

    @property
    def n(self) -> int:
        """Number of paired episodes."""
        return self.both_fail + self.candidate_only + self.baseline_only + self.neither

    @property
    def discordant(self) -> int:
        """Pairs where exactly one policy failed."""
        return self.candidate_only + self.baseline_only

    @property
    def candidate_rate(self) -> float:
        """Candidate's failure rate (0.0 for an empty table)."""
        return (self.both_fail + self.candidate_only) / self.n if self.n else 0.0

    @property
    def baseline_rate(self) -> float:
        """Baseline's failure rate (0.0 for an empty table)."""
        return (self.both_fail + self.baseline_only) / self.n if self.n else 0.0

    @property
    def difference(self) -> float:
        """Candidate minus baseline failure rate (0.0 for an empty table)."""
        return (self.candidate_only - self.baseline_only) / self.n if self.n else 0.0

    def swapped(self) -> PairedTable:
        """The same pairs with the roles of candidate and baseline exchanged."""
        return PairedTable(self.both_fail, self.baseline_only, self.candidate_only, self.neither)


def _as_bool_array(values: Sequence[bool], name: str) -> np.ndarray:
    array = np.asarray(values)
    if array.ndim != 1:
        raise RegressError(f"{name} outcomes must be a flat sequence, got shape {array.shape}")
    if array.dtype != bool:
        if array.size and not np.isin(array, (0, 1)).all():
            raise RegressError(f"{name} outcomes must be booleans (True = failed) or 0/1")
        array = array.astype(bool)
    return array


# ---------------------------------------------------------------------------------------------
# Difference of paired proportions and McNemar


def _newcombe_bounds(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised Newcombe (1998) method 10 interval for ``(a + b) / n - (a + c) / n``."""
    a, b, c, d = (np.asarray(x, dtype=float) for x in (a, b, c, d))
    n = a + b + c + d
    size = np.where(n > 0, n, 1.0)
    p1, p2 = (a + b) / size, (a + c) / size
    l1, u1 = wilson_bounds(a + b, n, z)
    l2, u2 = wilson_bounds(a + c, n, z)
    # correlation of the two margins, with Newcombe's correction: a positive ad - bc is reduced
    # by n/2 (floored at 0); zero if a margin is empty (a rate of 0 or 1)
    margins = (a + b) * (c + d) * (a + c) * (b + d)
    cross = a * d - b * c
    cross = np.where(cross > n / 2.0, cross - n / 2.0, np.where(cross >= 0.0, 0.0, cross))
    phi = np.where(margins > 0, cross / np.sqrt(np.where(margins > 0, margins, 1.0)), 0.0)
    down1, up2 = p1 - l1, u2 - p2
    up1, down2 = u1 - p1, p2 - l2
    estimate = p1 - p2
    low = estimate - np.sqrt(np.maximum(down1**2 - 2.0 * phi * down1 * up2 + up2**2, 0.0))
    high = estimate + np.sqrt(np.maximum(up1**2 - 2.0 * phi * up1 * down2 + down2**2, 0.0))
    low = np.where(n > 0, np.clip(low, -1.0, 1.0), -1.0)
    high = np.where(n > 0, np.clip(high, -1.0, 1.0), 1.0)
    return low, high


def paired_difference_interval(table: PairedTable, confidence: float = 0.95) -> tuple[float, float]:
    """Confidence interval for candidate minus baseline failure rate on paired episodes.

    Newcombe's hybrid score interval for paired proportions (Newcombe 1998, Stat. Med.
    17:2635, method 10): the Wilson intervals ``(l1, u1)`` and ``(l2, u2)`` of the two failure
    rates are combined by "square and add", corrected for the correlation ``phi`` of the paired
    outcomes::

        low  = d - sqrt((p1 - l1)^2 - 2 phi (p1 - l1)(u2 - p2) + (u2 - p2)^2)
        high = d + sqrt((u1 - p1)^2 - 2 phi (u1 - p1)(p2 - l2) + (p2 - l2)^2)

    where ``phi = (ad - bc) / sqrt(efgh)`` over the margins ``e, f, g, h``, with Newcombe's
    correction (``ad - bc`` above ``n/2`` is reduced by ``n/2``, between 0 and ``n/2`` it counts
    as 0) and ``phi = 0`` when a margin is empty.

    Why this one rather than Tango's score interval: it has a closed form (no root finding, so
    it vectorises over thousands of Monte Carlo tables), Newcombe found its coverage close to
    nominal with few aberrations for small ``n`` and rates near 0 (ours: failure rates of a
    few percent), it inherits the Wilson intervals' behaviour at zero counts, so it is finite
    and non-degenerate for any table (all zeros included), and it always contains the
    estimate.

    Args:
        table: The paired counts.
        confidence: Two-sided confidence level.

    Returns:
        ``(low, high)`` within ``[-1, 1]``; ``(-1.0, 1.0)`` for an empty table.
    """
    z = two_sided_z(confidence)
    low, high = _newcombe_bounds(
        np.array(table.both_fail), np.array(table.candidate_only),
        np.array(table.baseline_only), np.array(table.neither), z,
    )
    return float(low), float(high)


def mcnemar_exact(table: PairedTable, alternative: str = "two-sided") -> float:
    """Exact McNemar p-value of a paired table (:func:`policies.stats.mcnemar_p` of its discordant counts).

    Args:
        table: The paired counts.
        alternative: ``"two-sided"``; ``"greater"`` (the candidate fails more often: the one
            the regression gate uses); or ``"less"``.

    Returns:
        The p-value; 1.0 when there are no discordant pairs.
    """
    return mcnemar_p(table.candidate_only, table.baseline_only, alternative)


def _mcnemar_greater(candidate_only: np.ndarray, baseline_only: np.ndarray) -> np.ndarray:
    """Vectorised one-sided exact McNemar p-value, ``P(X >= candidate_only)``, X ~ Bin(m, 1/2)."""
    b = np.asarray(candidate_only)
    m = b + np.asarray(baseline_only)
    return np.where(m > 0, stats.binom.sf(b - 1, m, 0.5), 1.0)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values.

    The ``i``-th smallest of ``m`` p-values (counting from 0) is multiplied by ``m - i``, then a
    running maximum keeps the adjusted values in the order of the raw ones, and they are capped
    at 1. Rejecting every hypothesis whose adjusted p-value is below ``alpha`` controls the
    family-wise error rate at ``alpha``.

    Args:
        p_values: Raw p-values, each in ``[0, 1]``.

    Returns:
        Adjusted p-values in the input order (empty for no p-values).
    """
    count = len(p_values)
    return weighted_holm(p_values, [1.0] * count) if count else []


def weighted_holm(p_values: Sequence[float], weights: Sequence[float]) -> list[float]:
    """Weighted Holm step-down adjusted p-values (Holm 1979).

    Hypothesis ``i`` is first tested at ``alpha * w_i`` (weights normalised to sum to 1); each
    rejection hands its weight on to the hypotheses still standing. Sorted by ``p_i / w_i``,
    the ``k``-th adjusted p-value is the running maximum of ``p_(k) * W_k / w_(k)``, where
    ``W_k`` is the total weight of the hypotheses from the ``k``-th on, capped at 1. Equal
    weights give :func:`holm`.

    Args:
        p_values: Raw p-values, each in ``[0, 1]``.
        weights: Positive weight per hypothesis (any scale).

    Returns:
        Adjusted p-values in the input order.
    """
    p = np.asarray(p_values, dtype=float)
    w = np.asarray(weights, dtype=float)
    if p.ndim != 1 or p.shape != w.shape:
        raise RegressError(f"need one weight per p-value: {p.size} p-values, {w.size} weights")
    if np.isnan(p).any() or (p < 0).any() or (p > 1).any():
        raise RegressError("p-values must lie in [0, 1]")
    if not (w > 0).all():
        raise RegressError("weights must be positive")
    w = w / w.sum()
    order = np.argsort(p / w, kind="stable")
    remaining = np.cumsum(w[order][::-1])[::-1]  # weight of the hypotheses from k on
    stepped = np.maximum.accumulate(p[order] * remaining / w[order])
    adjusted = np.empty(p.size)
    adjusted[order] = np.minimum(stepped, 1.0)
    return adjusted.tolist()


# ---------------------------------------------------------------------------------------------
# Verdicts


@dataclass(frozen=True)
class Comparison:
    """The verdict on one paired table, with the numbers behind it.

    Attributes:
        table: The paired counts.
        margin: Non-inferiority margin on the failure-rate difference.
        alpha: Level of the FAIL test; the interval is two-sided ``1 - alpha``.
        difference: Candidate minus baseline failure rate.
        interval: Newcombe interval of the difference at ``1 - alpha``.
        p_value: One-sided exact McNemar p-value (candidate fails more).
        adjusted_p: The p-value after the gate's multiplicity adjustment (:func:`compare_scenarios`: the raw
            p-value scaled by ``alpha`` over the level the family tested it at), ``p_value`` if unadjusted.
        verdict: PASS, FAIL or INCONCLUSIVE.
        reason: One line for humans.
    """

    table: PairedTable
    margin: float
    alpha: float
    difference: float
    interval: tuple[float, float]
    p_value: float
    adjusted_p: float
    verdict: Verdict
    reason: str


def _decide(
    upper: np.ndarray, difference: np.ndarray, p_value: np.ndarray, margin: float, alpha: float
) -> np.ndarray:
    """The decision rule, vectorised: PASS, else FAIL, else INCONCLUSIVE (integer codes)."""
    upper, difference, p_value = np.asarray(upper), np.asarray(difference), np.asarray(p_value)
    return np.where(
        upper < margin,
        _PASS,
        np.where((p_value < alpha) & (difference > 0), _FAIL, _INCONCLUSIVE),
    )


def _pp(value: float) -> str:
    return f"{100 * value:+.1f} pp"


def _family_text(family: int | None) -> str:
    """The family an adjusted p-value was adjusted over, in words: ``3 scenarios and the pooled test``."""
    if family is None:
        return "the tests of the run"
    return f"{family} scenario{'s' if family != 1 else ''} and the pooled test"


def _reason(table: PairedTable, verdict: Verdict, interval: tuple[float, float], p_value: float,
            adjusted_p: float, margin: float, alpha: float, family: int | None = None) -> str:
    rates = (f"{table.n} paired episodes, failure rate {100 * table.candidate_rate:.1f}% vs "
             f"{100 * table.baseline_rate:.1f}% ({_pp(table.difference)}, "
             f"{100 * (1 - alpha):g}% CI {_pp(interval[0])} to {_pp(interval[1])})")
    p_text = f"one-sided exact McNemar p = {p_value:.3g}"
    if adjusted_p != p_value:
        p_text += f" (Holm-adjusted over {_family_text(family)}: {adjusted_p:.3g})"
    if verdict is Verdict.PASS:
        return f"not worse by {_pp(margin)} or more: {rates}; CI upper end below the margin"
    if verdict is Verdict.FAIL:
        return f"candidate fails more often: {rates}; {p_text} < {alpha:g}"
    return (f"cannot tell: {rates}; CI upper end reaches the {_pp(margin)} margin and "
            f"{p_text} is not below {alpha:g}")


def compare(
    table: PairedTable, margin: float, alpha: float = DEFAULT_ALPHA, adjusted_p: float | None = None,
    rejected: bool | None = None, family: int | None = None,
) -> Comparison:
    """Verdict on one paired table (see the module docstring for the rule).

    PASS when the upper end of the two-sided ``1 - alpha`` Newcombe interval of the difference
    is below ``margin``; else FAIL when the one-sided exact McNemar p-value (``adjusted_p`` if
    given) is below ``alpha`` and the difference is positive; else INCONCLUSIVE.

    Args:
        table: The paired counts.
        margin: Non-inferiority margin on the failure-rate difference, in ``[0, 1)``.
        alpha: Level of the FAIL test.
        adjusted_p: The table's p-value after a multiplicity adjustment (the gate's family of
            tests); must not be below the raw one-sided p-value.
        rejected: The multiplicity procedure's decision on "the candidate does not fail more often",
            when it made one: it replaces ``adjusted_p < alpha`` in the FAIL rule.
        family: How many scenarios the adjustment's family held (beside the pooled test), for the reason's
            words; ``None``: not known.

    Returns:
        The :class:`Comparison`.
    """
    alpha = check_level(alpha, "alpha")
    if not 0.0 <= margin < 1.0:
        raise RegressError(f"margin must be in [0, 1), got {margin}")
    interval = paired_difference_interval(table, 1.0 - alpha)
    p_value = mcnemar_exact(table, "greater")
    if adjusted_p is None:
        adjusted_p = p_value
    elif not p_value - 1e-12 <= adjusted_p <= 1.0:
        raise RegressError(f"adjusted_p={adjusted_p} must lie between the raw p-value {p_value:.6g} and 1")
    decisive_p = adjusted_p if rejected is None else (0.0 if rejected else 1.0)
    verdict = _VERDICT_OF_CODE[int(_decide(interval[1], table.difference, decisive_p, margin, alpha))]
    return Comparison(
        table=table, margin=margin, alpha=alpha, difference=table.difference, interval=interval,
        p_value=p_value, adjusted_p=float(adjusted_p), verdict=verdict,
        reason=_reason(table, verdict, interval, p_value, float(adjusted_p), margin, alpha, family),
    )


def compare_scenarios(
    tables: Mapping[str, PairedTable],
    margin: float,
    alpha: float = DEFAULT_ALPHA,
    pooled_weight: float = DEFAULT_POOLED_WEIGHT,
    pooled_rejected: bool | None = None,
) -> tuple[dict[str, Comparison], Comparison]:
    """Per-scenario verdicts and the overall verdict: every scenario is a test in its own right.

    The scenarios' one-sided exact McNemar tests and the pooled table's form one family tested by
    :func:`dv2s_gym.regress.family.gate_rejections` (step-down weighted Bonferroni with Tarone's
    refinement for discrete tests): the family-wise false-alarm rate is at most ``alpha``, and a
    regression confined to one scenario is tested at nearly the scenarios' whole share of ``alpha``
    when the other scenarios have few discordant pairs. Each scenario's verdict is :func:`compare`
    with the family's decision; its ``adjusted_p`` is the raw p-value scaled by ``alpha`` over the
    level it was tested at (FAIL iff at most ``alpha``).

    The overall comparison is :func:`compare` on the pooled table, with its verdict replaced by the
    overall rule: FAIL if any scenario FAILs or the pooled comparison FAILs; PASS if the pooled
    comparison PASSes, no scenario FAILs and no scenario's unadjusted one-sided p-value is below
    ``alpha`` with the candidate failing more; else INCONCLUSIVE.

    Args:
        tables: Paired table per scenario name (at least one).
        margin: Non-inferiority margin, for the scenarios and the pooled table alike.
        alpha: Family-wise level of the FAIL tests.
        pooled_weight: Share of ``alpha`` the pooled test starts with, in ``(0, 1)``.
        pooled_rejected: The pooled hypothesis's rejection when another test decided it (a
            sequential test spending ``pooled_weight * alpha``); None: the fixed-size test.

    Returns:
        ``(per_scenario, overall)``.
    """
    if not tables:
        raise RegressError("compare_scenarios needs at least one scenario")
    names = list(tables)
    pooled_table = PairedTable.pooled([tables[name] for name in names])
    raw = [mcnemar_exact(tables[name], "greater") for name in names]
    pooled_raw = mcnemar_exact(pooled_table, "greater")
    decision = gate_rejections(raw, [tables[name].discordant for name in names],
                               0.0 if pooled_rejected else (1.0 if pooled_rejected is False else pooled_raw),
                               alpha, pooled_weight)
    adjusted, pooled_adjusted = decision.scaled_p(raw, pooled_raw, alpha)
    per_scenario = {
        name: compare(tables[name], margin, alpha, adjusted_p=max(p_adj, p_raw), rejected=hit, family=len(names))
        for name, p_raw, p_adj, hit in zip(names, raw, adjusted, decision.scenarios)
    }
    if pooled_rejected is not None:
        pooled_adjusted = pooled_raw
    pooled = compare(pooled_table, margin, alpha, adjusted_p=max(pooled_adjusted, pooled_raw),
                     rejected=decision.pooled, family=len(names))
    failed = [name for name in names if per_scenario[name].verdict is Verdict.FAIL]
    # a regression the family's adjustment cannot confirm still blocks PASS: see the module docstring
    flagged = [name for name, p_raw in zip(names, raw) if p_raw < alpha and tables[name].difference > 0]
    if failed or pooled.verdict is Verdict.FAIL:
        verdict = Verdict.FAIL
        which = []
        if failed:
            which.append("scenario" + ("s " if len(failed) > 1 else " ") + ", ".join(failed))
        if pooled.verdict is Verdict.FAIL:
            which.append("all scenarios pooled")
        reason = f"candidate fails more often in {' and in '.join(which)}; pooled: {pooled.reason}"
    elif pooled.verdict is Verdict.PASS and flagged:
        verdict = Verdict.INCONCLUSIVE
        reason = ("scenario" + ("s " if len(flagged) > 1 else " ") + ", ".join(flagged)
                  + f" fail{'' if len(flagged) > 1 else 's'} significantly more often on their own (one-sided exact "
                  f"McNemar p < {alpha:g} before adjusting for the {len(names)} scenarios tested), so the pooled PASS "
                  f"does not stand; pooled: {pooled.reason}")
    elif pooled.verdict is Verdict.PASS:
        verdict, reason = Verdict.PASS, f"no scenario fails or is significantly worse on its own; pooled: {pooled.reason}"
    else:
        verdict, reason = Verdict.INCONCLUSIVE, f"no scenario fails; pooled: {pooled.reason}"
    overall = dataclasses.replace(pooled, verdict=verdict, reason=reason)
    return per_scenario, overall


# ---------------------------------------------------------------------------------------------
# Sequential stopping


SPENDING = "obrien-fleming"
"""The alpha-spending function :class:`SequentialTest` uses (:func:`obrien_fleming_spending`), as reports name it."""


def obrien_fleming_spending(fraction: float, alpha: float) -> float:
    """Lan-DeMets O'Brien-Fleming-type spending: ``2 (1 - Phi(z_{1-alpha/2} / sqrt(t)))``.

    Spends almost nothing at early looks and nearly all of ``alpha`` at the end, so the final
    look is almost as powerful as a fixed-size test.
    """
    if fraction <= 0.0:
        return 0.0
    if fraction >= 1.0:
        return alpha
    return float(2.0 * stats.norm.sf(stats.norm.isf(alpha / 2.0) / math.sqrt(fraction)))


@functools.lru_cache(maxsize=512)
def _fair_coin_pmf(flips: int) -> np.ndarray:
    return stats.binom.pmf(np.arange(flips + 1), flips, 0.5)


@dataclass(frozen=True)
class Look:
    """One interim analysis of a :class:`SequentialTest`.

    Attributes:
        table: The cumulative paired counts at this look.
        fraction: Information fraction ``episodes / max_episodes`` (at most 1).
        fail_critical: FAIL needs ``candidate_only >= fail_critical`` (above the discordant
            count: FAIL impossible at this look).
        fail_alpha_spent: Type I error of FAIL spent up to and including this look (exact).
        pass_level: One-sided level given to PASS at this look (Bonferroni share).
        pass_upper: Upper end of the two-sided ``1 - 2 pass_level`` interval (None if no level).
        verdict: The verdict reached at this look, or None to keep going.
    """

    table: PairedTable
    fraction: float
    fail_critical: int
    fail_alpha_spent: float
    pass_level: float
    pass_upper: float | None
    verdict: Verdict | None


class SequentialTest:
    """Group-sequential regression test: decide after each batch, stop once settled.

    Call :meth:`update` with the cumulative paired table after each batch of episodes. It
    returns FAIL or PASS as soon as a boundary is crossed, INCONCLUSIVE at the last look
    (``max_episodes`` reached) if neither was, and None in between (keep going).

    FAIL boundary (level ``alpha``, exact): with the policies failing alike, the discordant
    pairs' signs (candidate or baseline failed) are fair coin flips whatever their number. At
    each look the critical count is the smallest ``c`` whose exact probability of first
    crossing now - computed by recursion over the coin sequence, given the discordant counts
    at this and the earlier looks, and ignoring stops for PASS (non-binding) - is below the
    alpha allotted so far by the O'Brien-Fleming spending function minus what the earlier looks spent. So the
    probability of a false FAIL is at most ``alpha`` for any discordance and any look schedule
    that does not depend on the outcomes. The last look spends all that is left; with a single
    look this is exactly :func:`compare`'s FAIL test.

    PASS boundary (level ``alpha / 2``, like :func:`compare`): the same spending function
    shares ``alpha / 2`` between the looks; a look allotted ``a_k`` PASSes when the upper end of
    the two-sided ``1 - 2 a_k`` Newcombe interval is below the margin. By Bonferroni the chance
    of a false PASS over all looks is at most ``alpha / 2`` (as far as the interval's coverage is
    nominal), a conservative choice that needs no joint distribution of the looks.

    Args:
        margin: Non-inferiority margin on the failure-rate difference.
        alpha: Level of the FAIL test (PASS gets ``alpha / 2``).
        max_episodes: Paired episodes at the last look (the information fraction's unit).
        stop_for_pass: stop at an interim look that PASSes (default); when False, PASS is only
            decided at the last look, with the whole ``alpha / 2`` (as :func:`compare` does), so
            every planned episode runs unless a FAIL boundary is crossed.
    """

    def __init__(
        self,
        margin: float,
        alpha: float = DEFAULT_ALPHA,
        *,
        max_episodes: int,
        stop_for_pass: bool = True,
    ) -> None:
        if not 0.0 <= margin < 1.0:
            raise RegressError(f"margin must be in [0, 1), got {margin}")
        if operator.index(max_episodes) < 1:
            raise RegressError(f"max_episodes must be positive, got {max_episodes}")
        self.margin = float(margin)
        self.alpha = check_level(alpha, "alpha")
        self.max_episodes = int(max_episodes)
        self.spending = SPENDING
        self.stop_for_pass = bool(stop_for_pass)
        self._spend = obrien_fleming_spending
        self._continuing = np.ones(1)  # P(S = s and no FAIL yet) for s candidate-only of m discordant
        self._fail_spent = 0.0
        self._pass_spent = 0.0
        self._last = PairedTable()
        self.looks: list[Look] = []
        self.verdict: Verdict | None = None

    def _check_cumulative(self, table: PairedTable) -> None:
        last = self._last
        counts = ("both_fail", "candidate_only", "baseline_only", "neither")
        shrunk = [name for name in counts if getattr(table, name) < getattr(last, name)]
        if shrunk:
            raise RegressError(f"update needs the cumulative table: {', '.join(shrunk)} went down "
                             f"since the last look")
        if table.n <= last.n:
            raise RegressError(f"update needs new episodes: {table.n} paired episodes, {last.n} at the last look")

    def _fail_boundary(self, table: PairedTable, final: bool, fraction: float) -> int:
        """Critical candidate-only count at this look; updates the exact FAIL bookkeeping."""
        new_pairs = table.discordant - self._last.discordant
        continuing = np.convolve(self._continuing, _fair_coin_pmf(new_pairs))
        budget = (self.alpha if final else self._spend(fraction, self.alpha)) - self._fail_spent
        tail = np.append(np.cumsum(continuing[::-1])[::-1], 0.0)  # tail[s] = P(S >= s, continuing)
        below = np.flatnonzero(tail < budget)
        critical = int(below[0]) if below.size else table.discordant + 1
        self._fail_spent += float(tail[critical]) if critical <= table.discordant else 0.0
        continuing[critical:] = 0.0
        self._continuing = continuing
        return critical

    def update(self, table: PairedTable) -> Verdict | None:
        """Analyse the cumulative table after a batch.

        Args:
            table: All paired episodes so far (counts never go down between looks).

        Returns:
            PASS or FAIL when a boundary is crossed, INCONCLUSIVE at the last look otherwise,
            None to keep going.

        Raises:
            SequenceStoppedError (a RuntimeError): If the test already stopped.
            RegressError (a ValueError): If the table is not cumulative or has no new episodes.
        """
        if self.verdict is not None:
            raise SequenceStoppedError(f"the test already stopped with {self.verdict.value.upper()}")
        self._check_cumulative(table)
        final = table.n >= self.max_episodes
        fraction = min(1.0, table.n / self.max_episodes)
        critical = self._fail_boundary(table, final, fraction)
        pass_total = self.alpha / 2.0
        if final:
            pass_level = pass_total - self._pass_spent
        elif self.stop_for_pass:
            pass_level = self._spend(fraction, pass_total) - self._pass_spent
        else:
            pass_level = 0.0
        self._pass_spent += pass_level
        upper = None
        if pass_level > 0.0:
            upper = paired_difference_interval(table, 1.0 - 2.0 * pass_level)[1]
        verdict: Verdict | None = None
        if upper is not None and upper < self.margin:
            verdict = Verdict.PASS
        elif table.candidate_only >= critical and table.difference > 0:
            verdict = Verdict.FAIL
        elif final:
            verdict = Verdict.INCONCLUSIVE
        self.looks.append(Look(table, fraction, critical, self._fail_spent, pass_level, upper, verdict))
        self._last = table
        self.verdict = verdict
        return verdict
