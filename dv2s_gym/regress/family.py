"""The gate's family of tests: every scenario is a test in its own right, beside the pooled one.

A regression confined to one scenario must not be averaged away by the others, and a run of many
scenarios must not raise false alarms just because it tests many. :func:`gate_rejections` decides,
at a family-wise level ``alpha``, which of these hypotheses to reject ("the candidate does not fail
more often"):

- one per scenario, tested by the one-sided exact McNemar test on its paired table;
- one for all scenarios pooled (the same test on the summed table), which catches a small
  regression spread over many scenarios.

The procedure is a step-down (Holm-type) weighted Bonferroni procedure with Tarone's (1990)
refinement for discrete tests:

1. The pooled test starts with ``pooled_weight * alpha``; the scenarios share the rest.
2. The scenarios' share goes only to scenarios that *can* reach it: given its ``m`` discordant
   pairs, a scenario's exact p-value is at least ``0.5 ** m`` (its smallest possible value). With a
   budget ``B``, Tarone's ``K`` is the smallest ``K >= 1`` such that at most ``K`` scenarios have a
   smallest possible p-value at or below ``B / K``; each scenario is tested at ``B / K``. Scenarios
   where both policies failed alike on nearly every episode (few discordant pairs) cannot reject and
   take nothing from the others, so one scenario whose candidate newly fails on a third of its
   episodes is tested at nearly the whole share instead of ``1 / (number of scenarios)`` of it.
3. Step down: a rejected scenario leaves the family (Tarone's ``K`` is recomputed over the rest);
   once the pooled test rejects, its share goes to the scenarios; once every scenario is rejected,
   the pooled test gets the whole ``alpha``. Repeat until nothing more is rejected.

Why the family-wise error rate is at most ``alpha``: given the discordant counts (the McNemar test
conditions on them, and the scenarios are independent), each critical level depends only on the
set already rejected and never goes down when that set grows, and when exactly the false
hypotheses have been rejected the true ones' levels add up to at most ``alpha`` (Tarone: at most
``K`` testable scenarios at ``B / K`` each, the untestable ones cannot reject; plus the pooled
share). These are the monotonicity and single-step conditions of Goeman & Solari (2010, "The
sequential rejection principle of familywise error control"), under which a step-down procedure
controls the family-wise error rate. ``bench/calibrate_regress.py`` measures it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from dv2s_gym.regress.errors import RegressError

__all__ = ["DEFAULT_POOLED_WEIGHT", "FamilyDecision", "gate_rejections", "tarone_level", "smallest_p_value"]

DEFAULT_POOLED_WEIGHT = 0.5
"""Share of ``alpha`` the pooled test starts with; the scenarios share the rest (Tarone)."""


def smallest_p_value(discordant: int) -> float:
    """The smallest one-sided exact McNemar p-value ``m`` discordant pairs can give: ``0.5 ** m`` (1 for none)."""
    return 1.0 if discordant <= 0 else 0.5 ** int(discordant)


def tarone_level(smallest: Sequence[float], budget: float) -> float:
    """Tarone's per-test level for a budget: ``budget / K`` for the smallest ``K >= 1`` with at most ``K``
    tests whose smallest possible p-value is at or below ``budget / K`` (``budget`` when no test is left)."""
    values = np.sort(np.asarray(smallest, dtype=float))
    for k in range(1, max(1, values.size) + 1):
        level = budget / k
        if int(np.searchsorted(values, level, side="right")) <= k:
            return level
    return budget / max(1, values.size)  # not reached: K = number of tests always qualifies


@dataclass(frozen=True)
class FamilyDecision:
    """Which hypotheses the gate rejects, and the level each was last tested at.

    Attributes:
        scenarios: rejection per scenario (in the input order).
        pooled: the pooled hypothesis is rejected.
        scenario_levels: the level each scenario was tested at when the procedure stopped (or was rejected).
        pooled_level: the level of the pooled test when the procedure stopped (or it was rejected).
    """

    scenarios: tuple[bool, ...]
    pooled: bool
    scenario_levels: tuple[float, ...]
    pooled_level: float

    def scaled_p(self, p_values: Sequence[float], pooled_p: float, alpha: float) -> tuple[list[float], float]:
        """The p-values scaled by ``alpha / level`` (capped at 1): a hypothesis is rejected iff its scaled
        p-value is at most ``alpha``, so they read like adjusted p-values against ``alpha``."""
        scaled = [min(1.0, p * alpha / level) if level > 0 else 1.0
                  for p, level in zip(p_values, self.scenario_levels)]
        pooled = min(1.0, pooled_p * alpha / self.pooled_level) if self.pooled_level > 0 else 1.0
        return scaled, pooled


def gate_rejections(p_values: Sequence[float], discordant: Sequence[int], pooled_p: float, alpha: float,
                    pooled_weight: float = DEFAULT_POOLED_WEIGHT) -> FamilyDecision:
    """Run the step-down procedure of the module docstring.

    Args:
        p_values: one-sided exact McNemar p-value per scenario.
        discordant: discordant pairs per scenario (the smallest possible p-value is ``0.5 ** m``).
        pooled_p: the pooled table's one-sided exact McNemar p-value.
        alpha: family-wise level.
        pooled_weight: share of ``alpha`` the pooled test starts with, in ``(0, 1)``.

    Returns:
        The :class:`FamilyDecision`.
    """
    if not 0.0 < alpha < 1.0:
        raise RegressError(f"alpha must be strictly between 0 and 1, got {alpha}")
    if not 0.0 < pooled_weight < 1.0:
        raise RegressError(f"pooled_weight must be strictly between 0 and 1, got {pooled_weight}")
    if len(p_values) != len(discordant):
        raise RegressError(f"need one discordant count per p-value: {len(p_values)} p-values, {len(discordant)} counts")
    p = np.asarray(p_values, dtype=float)
    smallest = np.array([smallest_p_value(m) for m in discordant])
    count = p.size
    rejected = np.zeros(count, dtype=bool)
    levels = np.zeros(count)
    pooled_rejected, pooled_level = False, 0.0
    while True:
        remaining = np.flatnonzero(~rejected)
        budget = alpha if pooled_rejected else alpha * (1.0 - pooled_weight)
        level = tarone_level(smallest[remaining], budget) if remaining.size else 0.0
        levels[remaining] = level
        new = remaining[p[remaining] <= level]
        if not pooled_rejected:
            pooled_level = alpha if not remaining.size else alpha * pooled_weight
        pooled_new = not pooled_rejected and pooled_p <= pooled_level
        if not new.size and not pooled_new:
            break
        rejected[new] = True
        pooled_rejected = pooled_rejected or pooled_new
    return FamilyDecision(tuple(bool(r) for r in rejected), bool(pooled_rejected),
                          tuple(float(v) for v in levels), float(pooled_level))
