"""Statistics of ``dv2s regress`` (dv2s_gym/regress/stats.py) and the primitives it shares with the model cards
(policies/stats.py: the Wilson interval, the exact McNemar test): reference values and verdict rules.

Their Monte Carlo calibration (false alarms, P(PASS) at the margin, power, on the paired-outcome model) is
bench/tests/test_regress_montecarlo.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from dv2s_gym.regress.family import gate_rejections, smallest_p_value, tarone_level
from dv2s_gym.regress.stats import (
    DEFAULT_ALPHA,
    DEFAULT_MARGIN,
    PairedTable,
    SequentialTest,
    Verdict,
    cluster_bootstrap_mean,
    compare,
    compare_scenarios,
    holm,
    mcnemar_exact,
    obrien_fleming_spending,
    paired_difference_interval,
    weighted_holm,
)
from policies.stats import StatisticsError, mcnemar_p, wilson_interval

Z95 = 1.959963984540054


# --- one proportion ---------------------------------------------------------------------------


def wilson_closed_form(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson (1927) as the roots of (p - phat)^2 = z^2 p (1 - p) / n, solved as a quadratic."""
    phat = k / n
    # (1 + z^2/n) p^2 - (2 phat + z^2/n) p + phat^2 = 0
    qa, qb, qc = 1 + z * z / n, -(2 * phat + z * z / n), phat * phat
    root = math.sqrt(qb * qb - 4 * qa * qc)
    return (-qb - root) / (2 * qa), (-qb + root) / (2 * qa)


@pytest.mark.parametrize("k,n", [(0, 1), (1, 1), (0, 10), (3, 10), (10, 10), (40, 800), (17, 23)])
def test_wilson_matches_the_quadratic_roots(k, n):
    low, high = wilson_interval(k, n)
    ref_low, ref_high = wilson_closed_form(k, n)
    assert low == pytest.approx(max(ref_low, 0.0), abs=1e-12)
    assert high == pytest.approx(min(ref_high, 1.0), abs=1e-12)


def test_wilson_textbook_value_and_empty_sample():
    # 0 of 3: the upper end is z^2 / (n + z^2)
    assert wilson_interval(0, 3)[1] == pytest.approx(Z95**2 / (3 + Z95**2))
    assert wilson_interval(0, 0) == (0.0, 1.0)
    # 90 % interval is narrower
    assert wilson_interval(5, 50, 0.9)[1] < wilson_interval(5, 50)[1]


def test_interval_arguments_are_checked():
    with pytest.raises(StatisticsError, match="need 0 <= k <= n, got k=5, n=3"):
        wilson_interval(5, 3)
    with pytest.raises(StatisticsError, match="confidence must be strictly between 0 and 1"):
        wilson_interval(1, 3, confidence=1.0)
    with pytest.raises(TypeError):
        wilson_interval(1.5, 3)


# --- cluster bootstrap ------------------------------------------------------------------------


def test_cluster_bootstrap_estimate_is_the_pooled_mean_and_resamples_whole_groups():
    groups = [[1.0, 1.0, 1.0], [0.0], [0.0, 0.0], [1.0, 0.0]]
    estimate, low, high = cluster_bootstrap_mean(groups, n_resamples=4000, seed=1)
    assert estimate == pytest.approx(4 / 8)
    assert 0.0 <= low < estimate < high <= 1.0
    # identical groups: every resample has the same mean
    assert cluster_bootstrap_mean([[0.0, 1.0]] * 5) == (0.5, 0.5, 0.5)
    # a single group says nothing about between-group variation
    assert cluster_bootstrap_mean([[0.0, 1.0, 1.0]])[1:] == (pytest.approx(2 / 3), pytest.approx(2 / 3))
    # reproducible by seed
    assert cluster_bootstrap_mean(groups, seed=7) == cluster_bootstrap_mean(groups, seed=7)


def test_cluster_bootstrap_is_wider_than_episode_level_when_scenarios_differ():
    rng = np.random.default_rng(0)
    rates = [0.01, 0.02, 0.05, 0.1, 0.3, 0.02, 0.04, 0.2]  # heterogeneous scenarios
    groups = [list(rng.random(100) < r) for r in rates]
    rate, low, high = cluster_bootstrap_mean([[float(o) for o in g] for g in groups], n_resamples=4000)
    k = sum(sum(g) for g in groups)
    w_low, w_high = wilson_interval(k, 800)
    assert rate == pytest.approx(k / 800)
    assert high - low > 1.3 * (w_high - w_low)
    with pytest.raises(ValueError):
        cluster_bootstrap_mean([[], []])


# --- paired table -----------------------------------------------------------------------------


def test_paired_table_from_outcomes():
    candidate = [True, True, False, False, True, False]
    baseline = [True, False, True, False, False, False]
    table = PairedTable.from_outcomes(candidate, baseline)
    assert table == PairedTable(both_fail=1, candidate_only=2, baseline_only=1, neither=2)
    assert table.n == 6 and table.discordant == 3
    assert table.candidate_rate == pytest.approx(3 / 6)
    assert table.baseline_rate == pytest.approx(2 / 6)
    assert table.difference == pytest.approx(1 / 6)
    assert PairedTable.from_outcomes(np.array([1, 0]), np.array([0, 0])).candidate_only == 1
    assert table + table == PairedTable(2, 4, 2, 4) == PairedTable.pooled([table, table])
    assert PairedTable().difference == 0.0 and PairedTable().n == 0


def test_paired_table_refuses_bad_input_and_names_the_problem():
    with pytest.raises(ValueError, match="candidate has 3 episodes, baseline has 2"):
        PairedTable.from_outcomes([True, False, True], [True, False])
    with pytest.raises(ValueError, match="baseline outcomes must be booleans"):
        PairedTable.from_outcomes([True, False], [0.5, 1])
    with pytest.raises(ValueError, match="candidate_only must not be negative"):
        PairedTable(1, -1, 0, 0)
    with pytest.raises(TypeError, match="neither must be an integer"):
        PairedTable(1, 1, 0, 2.5)


# --- difference interval ----------------------------------------------------------------------


def newcombe_reference(a: int, b: int, c: int, d: int, z: float = Z95) -> tuple[float, float]:
    """Newcombe (1998) method 10, written out from the paper's formulas for one table."""
    n = a + b + c + d
    e, f, g, h = a + b, c + d, a + c, b + d
    p1, p2 = e / n, g / n
    l1, u1 = wilson_closed_form(e, n, z)
    l2, u2 = wilson_closed_form(g, n, z)
    l1, l2, u1, u2 = max(l1, 0), max(l2, 0), min(u1, 1), min(u2, 1)
    if e * f * g * h == 0:
        phi = 0.0
    else:
        numerator = a * d - b * c
        if numerator > n / 2:
            numerator -= n / 2
        elif numerator >= 0:
            numerator = 0
        phi = numerator / math.sqrt(e * f * g * h)
    delta = math.sqrt((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2)
    epsilon = math.sqrt((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    return p1 - p2 - delta, p1 - p2 + epsilon


def test_newcombe_published_example():
    # Cavo et al. (2012) in Fagerland, Lydersen & Laake, "Statistical Analysis of Contingency
    # Tables" (2017), ch. 8: table 59, 6 / 16, 80; difference -0.0621, 95 % CI -0.1186 to -0.0046
    table = PairedTable(both_fail=59, candidate_only=6, baseline_only=16, neither=80)
    low, high = paired_difference_interval(table)
    assert table.difference == pytest.approx(-0.0621, abs=5e-5)
    assert low == pytest.approx(-0.1186, abs=5e-5)
    assert high == pytest.approx(-0.0046, abs=5e-5)


@pytest.mark.parametrize("cells", [(1, 1, 7, 12), (12, 2, 1, 19), (0, 3, 1, 40), (5, 30, 10, 755), (2, 0, 0, 9),
                                   (40, 1, 0, 1), (0, 5, 5, 0), (3, 3, 3, 3)])
def test_newcombe_matches_an_independent_transcription(cells):
    assert paired_difference_interval(PairedTable(*cells)) == pytest.approx(newcombe_reference(*cells), abs=1e-12)


@pytest.mark.parametrize("cells", [(0, 0, 0, 0), (0, 0, 0, 1), (0, 0, 0, 3), (3, 0, 0, 0), (0, 2, 0, 0), (0, 0, 2, 0),
                                   (1, 0, 0, 1), (0, 1, 1, 0), (0, 0, 0, 10_000), (5, 0, 0, 995)])
def test_newcombe_handles_zero_cells_without_nan(cells):
    table = PairedTable(*cells)
    low, high = paired_difference_interval(table)
    assert np.isfinite([low, high]).all()
    assert -1.0 <= low <= table.difference <= high <= 1.0
    if table.n:
        assert low < high


def test_newcombe_properties():
    table = PairedTable(3, 12, 5, 180)
    low, high = paired_difference_interval(table)
    assert low < table.difference < high
    # symmetric under swapping the policies
    s_low, s_high = paired_difference_interval(table.swapped())
    assert (s_low, s_high) == pytest.approx((-high, -low), abs=1e-14)
    # narrows with n (same proportions, ten times the episodes)
    big = PairedTable(30, 120, 50, 1800)
    b_low, b_high = paired_difference_interval(big)
    assert b_high - b_low < (high - low) / 2.5
    # a higher confidence is wider
    w_low, w_high = paired_difference_interval(table, 0.99)
    assert w_low < low and w_high > high
    # no discordant pairs: symmetric around 0
    z_low, z_high = paired_difference_interval(PairedTable(0, 0, 0, 3))
    assert z_low == pytest.approx(-z_high) and z_high == pytest.approx(Z95**2 / (3 + Z95**2))
    assert paired_difference_interval(PairedTable()) == (-1.0, 1.0)


# --- McNemar and Holm -------------------------------------------------------------------------


def binomial_tail(k: int, m: int) -> float:
    return sum(math.comb(m, i) for i in range(k, m + 1)) / 2**m


@pytest.mark.parametrize("b,c", [(0, 0), (1, 0), (0, 1), (5, 1), (10, 2), (7, 7), (3, 12), (30, 10), (1, 9)])
def test_mcnemar_exact_is_the_binomial_sum_over_discordant_pairs(b, c):
    table = PairedTable(4, b, c, 50)
    m = b + c
    greater = binomial_tail(b, m) if m else 1.0
    less = binomial_tail(c, m) if m else 1.0
    assert mcnemar_exact(table, "greater") == pytest.approx(greater, rel=1e-12)
    assert mcnemar_exact(table, "less") == pytest.approx(less, rel=1e-12)
    assert mcnemar_exact(table) == pytest.approx(min(1.0, 2 * min(greater, less)), rel=1e-12)
    assert mcnemar_p(b, c, "greater") == mcnemar_exact(table, "greater")  # the table's test is the counts' test


def test_mcnemar_known_values():
    assert mcnemar_exact(PairedTable(0, 5, 0, 0), "greater") == pytest.approx(1 / 32)
    assert mcnemar_exact(PairedTable(0, 5, 0, 0)) == pytest.approx(1 / 16)
    assert mcnemar_exact(PairedTable(10, 0, 0, 10), "greater") == 1.0
    with pytest.raises(StatisticsError, match="alternative must be 'two-sided', 'greater' or 'less'"):
        mcnemar_exact(PairedTable(), "bigger")


def test_holm_examples():
    # by hand: sorted 0.01, 0.02, 0.03, 0.04 times 4, 3, 2, 1 -> 0.04, 0.06, 0.06, 0.06 (running max)
    assert holm([0.01, 0.04, 0.03, 0.02]) == pytest.approx([0.04, 0.06, 0.06, 0.06])
    assert holm([0.5, 0.01]) == pytest.approx([0.5, 0.02])
    assert holm([0.3, 0.6, 0.9]) == pytest.approx([0.9, 1.0, 1.0])  # capped at 1
    assert holm([0.02]) == [0.02]
    assert holm([]) == []
    with pytest.raises(ValueError):
        holm([0.1, 1.5])


def test_holm_is_monotone_and_at_least_the_raw_p_values():
    rng = np.random.default_rng(3)
    for _ in range(50):
        p = rng.random(rng.integers(1, 12)) ** 3
        adjusted = np.array(holm(p))
        order = np.argsort(p)
        assert (np.diff(adjusted[order]) >= -1e-15).all()
        assert (adjusted >= p - 1e-15).all() and (adjusted <= 1).all()


def test_weighted_holm():
    assert weighted_holm([0.01, 0.04, 0.03, 0.02], [1, 1, 1, 1]) == pytest.approx(holm([0.01, 0.04, 0.03, 0.02]))
    # weights 0.8 / 0.2: first step 0.03 / 0.8 = 0.0375 -> adjusted 0.0375; then 0.02 alone -> 0.02 -> max 0.0375
    assert weighted_holm([0.03, 0.02], [0.8, 0.2]) == pytest.approx([0.0375, 0.0375])
    assert weighted_holm([0.2, 0.002], [0.8, 0.2]) == pytest.approx([0.2, 0.01])
    with pytest.raises(ValueError):
        weighted_holm([0.1, 0.2], [1.0, 0.0])


# --- verdicts ---------------------------------------------------------------------------------


def test_too_small_to_tell_is_inconclusive_never_pass():
    for table in (PairedTable(0, 0, 0, 3), PairedTable(), PairedTable(0, 0, 0, 30), PairedTable(1, 0, 0, 20)):
        result = compare(table, margin=DEFAULT_MARGIN)
        assert result.verdict is Verdict.INCONCLUSIVE, result.reason
        assert result.reason.startswith("cannot tell")
    # three episodes with no failure: the interval's upper end is large
    assert compare(PairedTable(0, 0, 0, 3), 0.02).interval[1] > 0.5


def test_clear_regression_fails_and_says_why():
    result = compare(PairedTable(5, 30, 10, 755), margin=0.02)
    assert result.verdict is Verdict.FAIL
    assert result.p_value == pytest.approx(binomial_tail(30, 40))
    assert result.adjusted_p == result.p_value
    assert result.difference == pytest.approx(0.025)
    assert "candidate fails more often" in result.reason and "p = 0.00111" in result.reason
    assert "\n" not in result.reason


def test_shown_not_worse_passes():
    result = compare(PairedTable(10, 8, 9, 973), margin=0.02)
    assert result.verdict is Verdict.PASS
    assert result.interval[1] < 0.02
    assert result.reason.startswith("not worse")


def test_significantly_worse_but_within_the_margin_passes():
    # a +1 pp regression measured very precisely: non-inferior at a 2 pp margin
    table = PairedTable(100, 700, 400, 28800)
    assert mcnemar_exact(table, "greater") < 1e-10
    assert compare(table, margin=0.02).verdict is Verdict.PASS
    assert compare(table, margin=0.005).verdict is Verdict.FAIL


def test_candidate_better_is_never_fail():
    assert compare(PairedTable(5, 2, 30, 63), margin=0.0).verdict is not Verdict.FAIL
    assert compare(PairedTable(5, 2, 30, 63), margin=0.02).verdict is Verdict.PASS


def test_holm_adjusted_p_can_turn_fail_into_inconclusive():
    table = PairedTable(5, 22, 9, 364)  # p ~ 0.015
    assert compare(table, 0.02).verdict is Verdict.FAIL
    adjusted = compare(table, 0.02, adjusted_p=0.09)
    assert adjusted.verdict is Verdict.INCONCLUSIVE and adjusted.adjusted_p == 0.09
    assert "p = 0.0147 (Holm-adjusted over the tests of the run: 0.09)" in adjusted.reason
    in_family = compare(table, 0.02, adjusted_p=0.09, family=1)
    assert "(Holm-adjusted over 1 scenario and the pooled test: 0.09)" in in_family.reason
    with pytest.raises(ValueError):
        compare(table, 0.02, adjusted_p=0.001)  # below the raw p-value
    with pytest.raises(ValueError):
        compare(table, margin=-0.1)


def test_compare_scenarios_tests_every_scenario_in_the_family():
    tables = {
        "cut_in": PairedTable(2, 14, 2, 82),  # p ~ 0.002
        "lead_brakes": PairedTable(1, 3, 2, 94),
        "merge": PairedTable(0, 2, 2, 96),
    }
    per, overall = compare_scenarios(tables, margin=0.02)
    assert per["cut_in"].verdict is Verdict.FAIL
    assert per["lead_brakes"].verdict is Verdict.INCONCLUSIVE
    assert overall.verdict is Verdict.FAIL and "scenario cut_in" in overall.reason
    assert overall.table == PairedTable(3, 19, 6, 272)
    for comparison in per.values():  # the scaled p-value reads against alpha like an adjusted one
        assert comparison.adjusted_p >= comparison.p_value
        assert (comparison.adjusted_p <= DEFAULT_ALPHA) == (comparison.verdict is Verdict.FAIL)


def test_a_regression_in_one_scenario_is_not_averaged_away_by_fixes_elsewhere():
    # 0 % -> 30 % in one scenario of 40 episodes, 12 failures fixed elsewhere: the pooled table shows nothing
    tables = {"broken": PairedTable(0, 12, 0, 28), "fixed": PairedTable(0, 0, 12, 28)}
    tables.update({f"same{i}": PairedTable(1, 2, 2, 35) for i in range(19)})
    per, overall = compare_scenarios(tables, margin=0.02)
    assert per["broken"].verdict is Verdict.FAIL
    assert overall.verdict is Verdict.FAIL and "scenario broken" in overall.reason
    assert "all scenarios pooled" not in overall.reason
    # the scenarios that cannot reach a level take none of it: stronger than Holm over the 21 scenarios
    assert per["broken"].adjusted_p < holm([mcnemar_exact(t, "greater") for t in tables.values()])[0]


def test_tarone_levels_go_only_to_scenarios_that_can_reach_them():
    # a scenario with m discordant pairs cannot give p below 0.5 ** m
    assert smallest_p_value(0) == 1.0 and smallest_p_value(5) == 0.5 ** 5
    assert tarone_level([1.0] * 20 + [0.5 ** 6], 0.025) == 0.025  # only one can reach it
    assert tarone_level([0.5 ** 10] * 4, 0.025) == pytest.approx(0.025 / 4)  # all four can
    # testable at budget / 2 are two of them: K = 2
    assert tarone_level([0.5 ** 10, 0.5 ** 10, 0.02, 0.02], 0.025) == pytest.approx(0.0125)
    decision = gate_rejections([0.001, 0.5, 0.5], [10, 3, 3], pooled_p=0.04, alpha=0.05)
    assert decision.scenarios == (True, False, False)
    # the pooled test keeps its share until every scenario is rejected
    assert decision.pooled_level == pytest.approx(0.025) and not decision.pooled
    # once the pooled test rejects, its share goes to the scenarios (step down)
    decision = gate_rejections([0.03, 0.5], [8, 1], pooled_p=0.02, alpha=0.05)
    assert decision.pooled and decision.scenarios == (True, False)
    assert decision.scenario_levels[0] == pytest.approx(0.05)
    with pytest.raises(ValueError, match="one discordant count per p-value"):
        gate_rejections([0.1], [1, 2], 0.5, 0.05)


def test_compare_scenarios_pass_and_inconclusive_overall():
    fine = {f"s{i}": PairedTable(3, 4, 4, 489) for i in range(4)}
    per, overall = compare_scenarios(fine, margin=0.02)
    assert overall.verdict is Verdict.PASS
    assert all(c.verdict is not Verdict.FAIL for c in per.values())
    small = {"a": PairedTable(0, 1, 0, 9), "b": PairedTable(0, 0, 1, 9)}
    assert compare_scenarios(small, 0.02)[1].verdict is Verdict.INCONCLUSIVE
    with pytest.raises(ValueError):
        compare_scenarios({}, 0.02)


def test_compare_scenarios_a_scenario_significantly_worse_on_its_own_blocks_pass():
    # 20 alike scenarios and one where the candidate fails in 8 more pairs than it wins: significant alone
    # (p = 0.02), not after adjusting for 21 scenarios; the pooled table alone would PASS
    tables = {f"s{i}": PairedTable(10, 3, 3, 200) for i in range(20)}
    tables["worse"] = PairedTable(10, 8, 1, 197)
    per, overall = compare_scenarios(tables, 0.02)
    assert per["worse"].verdict is Verdict.INCONCLUSIVE and per["worse"].p_value < 0.05
    pooled_only = compare(PairedTable.pooled(list(tables.values())), 0.02)
    assert pooled_only.verdict is Verdict.PASS
    assert overall.verdict is Verdict.INCONCLUSIVE and "scenario worse fails significantly" in overall.reason
    del tables["worse"]
    assert compare_scenarios(tables, 0.02)[1].verdict is Verdict.PASS


def test_compare_scenarios_pooled_regression_spread_over_scenarios_fails():
    # +3 pp in every scenario, none significant alone, clearly significant pooled
    tables = {f"s{i}": PairedTable(3, 7, 3, 187) for i in range(5)}
    per, overall = compare_scenarios(tables, 0.02)
    assert all(c.verdict is not Verdict.FAIL for c in per.values())
    assert overall.verdict is Verdict.FAIL and "all scenarios pooled" in overall.reason


# --- sequential test --------------------------------------------------------------------------


def test_spending_function():
    values = [obrien_fleming_spending(t, 0.05) for t in np.linspace(0, 1, 11)]
    assert values[0] == 0.0 and values[-1] == pytest.approx(0.05)
    assert (np.diff(values) > 0).all()
    # O'Brien-Fleming at t = 0.5, alpha 0.05: 2 (1 - Phi(1.96 / sqrt(0.5)))
    assert obrien_fleming_spending(0.5, 0.05) == pytest.approx(2 * stats.norm.sf(Z95 / math.sqrt(0.5)))


def test_sequential_stops_early_on_a_flagrant_regression_and_refuses_misuse():
    test = SequentialTest(DEFAULT_MARGIN, max_episodes=800)
    assert test.update(PairedTable(1, 4, 3, 152)) is None
    assert test.update(PairedTable(2, 30, 4, 284)) is Verdict.FAIL
    assert [look.verdict for look in test.looks] == [None, Verdict.FAIL]
    assert test.looks[-1].fail_alpha_spent <= obrien_fleming_spending(320 / 800, 0.05)
    with pytest.raises(RuntimeError):
        test.update(PairedTable(2, 30, 4, 400))
    test = SequentialTest(DEFAULT_MARGIN, max_episodes=800)
    test.update(PairedTable(1, 4, 3, 152))
    with pytest.raises(ValueError, match="candidate_only went down"):
        test.update(PairedTable(1, 3, 3, 200))
    with pytest.raises(ValueError, match="new episodes"):
        test.update(PairedTable(1, 4, 3, 152))


@pytest.mark.slow
def test_sequential_fail_error_is_exact_given_the_discordant_counts():
    # every sign sequence of 10 discordant pairs, seen at looks with 2, 5, 7, 10 of them: the
    # probability of a FAIL (fair coins) is the alpha the test says it spent, and at most alpha
    discordant, episodes = [2, 5, 7, 10], [40, 80, 120, 160]
    alpha = 0.25  # large, so that small counts can cross
    fails = 0
    for code in range(2**10):
        signs = [(code >> i) & 1 for i in range(10)]
        test = SequentialTest(margin=0.0, alpha=alpha, max_episodes=160)
        for m, n in zip(discordant, episodes):
            b = sum(signs[:m])
            verdict = test.update(PairedTable(0, b, m - b, n - m))
            if verdict is not None:
                break
        fails += verdict is Verdict.FAIL
        if len(test.looks) == 4:
            spent = test.looks[-1].fail_alpha_spent
    # PASS needs the interval's upper end below 0, which these counts never reach at margin 0
    assert fails / 2**10 == pytest.approx(spent, abs=1e-12)
    assert 0.5 * alpha < spent <= alpha
