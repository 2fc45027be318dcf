"""The Monte Carlo calibration of ``dv2s regress``'s statistics, on the paired-outcome model of
bench/research/regress_montecarlo.py: the model and sample-size formulas against reference values, and the rules of
dv2s_gym/regress/stats.py on simulated runs with fixed seeds (each result sits several standard errors from its
bound, so it does not hinge on the seed)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from bench.research.regress_montecarlo import (
    DOCUMENTED_BASELINE_RATE,
    DOCUMENTED_DELTA,
    DOCUMENTED_EPISODES,
    DOCUMENTED_POWER,
    MonteCarloRate,
    discordant_probability,
    paired_cell_probabilities,
    paired_sample_size,
    simulate_false_alarm,
    simulate_paired_outcomes,
    simulate_power,
    simulate_tables,
    simulate_unpaired_power,
    simulate_verdict_rates,
    unpaired_sample_size,
    verdicts_of_tables,
)
from dv2s_gym.regress.stats import (
    DEFAULT_ALPHA,
    DEFAULT_CORRELATION,
    DEFAULT_MARGIN,
    PairedTable,
    SequentialTest,
    Verdict,
    compare,
    compare_scenarios,
    paired_difference_interval,
)


# --- the model and sample sizes -----------------------------------------------------------------


def test_shared_difficulty_model_cells():
    both, cand_only, base_only, neither = paired_cell_probabilities(0.05, 0.08, 0.0)
    assert both == pytest.approx(0.05 * 0.08)
    cells = paired_cell_probabilities(0.05, 0.08, 0.5)
    assert sum(cells) == pytest.approx(1.0)
    # both-fail probability from scipy's bivariate normal CDF
    cov = [[1, 0.5], [0.5, 1]]
    reference = stats.multivariate_normal(mean=[0, 0], cov=cov).cdf([stats.norm.ppf(0.05), stats.norm.ppf(0.08)])
    assert cells[0] == pytest.approx(reference, abs=1e-5)
    assert paired_cell_probabilities(0.05, 0.08, 1.0)[0] == pytest.approx(0.05)
    # more correlation, fewer discordant pairs
    assert discordant_probability(0.05, 0.08, 0.9) < discordant_probability(0.05, 0.08, 0.5) < 0.05 * 0.92 + 0.08 * 0.95


def test_simulated_outcomes_follow_the_model():
    rng = np.random.default_rng(4)
    cand, base = simulate_paired_outcomes(2000, 0.05, 0.08, 0.5, 100, rng)
    assert cand.shape == base.shape == (100, 2000)
    observed = np.array([np.mean(cand & base), np.mean(cand & ~base), np.mean(~cand & base)])
    assert observed == pytest.approx(paired_cell_probabilities(0.05, 0.08, 0.5)[:3], abs=0.001)


def test_sample_size_formulas():
    # Connor (1987): psi = 0.122 (independent policies) -> (1.645 sqrt(.122) + .8416 sqrt(.1211))^2 / .0009
    z_a, z_b = stats.norm.isf(0.05), stats.norm.ppf(0.8)
    psi = 0.05 * 0.92 + 0.08 * 0.95
    expected = math.ceil((z_a * math.sqrt(psi) + z_b * math.sqrt(psi - 0.0009)) ** 2 / 0.0009)
    assert paired_sample_size(0.05, 0.03, discordance=psi) == expected
    assert paired_sample_size(0.05, 0.03, correlation=0.0) == expected
    # independent pairs need about what an unpaired design needs; correlation cuts it down
    unpaired = unpaired_sample_size(0.05, 0.03)
    assert abs(unpaired - expected) <= 5
    assert paired_sample_size(0.05, 0.03) < 0.85 * unpaired
    assert paired_sample_size(0.05, 0.03, correlation=0.9) < paired_sample_size(0.05, 0.03, correlation=0.5)
    # Fleiss without continuity correction, by hand for 5 % vs 8 %
    mean = 0.065
    by_hand = (z_a * math.sqrt(2 * mean * (1 - mean)) + z_b * math.sqrt(0.05 * 0.95 + 0.08 * 0.92)) ** 2 / 0.0009
    assert unpaired == math.ceil(by_hand)
    with pytest.raises(ValueError):
        paired_sample_size(0.05, 0.03, discordance=0.1, correlation=0.5)
    with pytest.raises(ValueError):
        paired_sample_size(0.05, 0.03, discordance=0.02)  # fewer discordant pairs than the difference


# --- compare() on simulated runs -----------------------------------------------------------------


def test_calibration_false_alarm_at_most_alpha():
    rng = np.random.default_rng(20261123)
    false_alarm = simulate_false_alarm(DOCUMENTED_EPISODES, repetitions=3000, rng=rng)
    assert false_alarm.interval()[0] <= DEFAULT_ALPHA
    assert false_alarm.rate <= DEFAULT_ALPHA


@pytest.mark.parametrize("n,p,rho", [(30, 0.2, 0.5), (120, 0.05, 0.0), (400, 0.1, 0.8)])
def test_calibration_false_alarm_other_designs(n, p, rho):
    rng = np.random.default_rng(n)
    false_alarm = simulate_false_alarm(n, p, correlation=rho, repetitions=2000, rng=rng)
    assert false_alarm.interval()[0] <= DEFAULT_ALPHA


def test_calibration_no_pass_when_the_difference_is_the_margin():
    rng = np.random.default_rng(1123)
    rates = simulate_verdict_rates(DOCUMENTED_EPISODES, DOCUMENTED_BASELINE_RATE,
                                   DOCUMENTED_BASELINE_RATE + DEFAULT_MARGIN, repetitions=3000, rng=rng)
    false_pass = rates[Verdict.PASS]
    assert false_pass.interval()[0] <= DEFAULT_ALPHA and false_pass.rate <= DEFAULT_ALPHA


def test_calibration_power_at_the_documented_episode_count():
    rng = np.random.default_rng(81123)
    power = simulate_power(DOCUMENTED_EPISODES, DOCUMENTED_BASELINE_RATE, DOCUMENTED_DELTA,
                           repetitions=3000, rng=rng)
    assert power.rate >= DOCUMENTED_POWER
    # the same episode count without pairing (each policy on its own scenes, Fisher's exact test) falls short
    unpaired = simulate_unpaired_power(DOCUMENTED_EPISODES, DOCUMENTED_BASELINE_RATE, DOCUMENTED_DELTA,
                                       repetitions=3000, rng=rng)
    assert unpaired.interval()[1] < DOCUMENTED_POWER


@pytest.mark.slow
def test_newcombe_coverage_by_simulation():
    # 95 % interval, one-sided misses at most ~2.5 % each side (allowing for its approximation)
    rng = np.random.default_rng(11)
    tables = simulate_tables(400, 0.05, 0.08, DEFAULT_CORRELATION, 4000, rng)
    truth = 0.03
    lows, highs = zip(*(paired_difference_interval(PairedTable(*map(int, row))) for row in tables))
    below, above = np.mean(np.array(highs) < truth), np.mean(np.array(lows) > truth)
    assert below < 0.04 and above < 0.04
    assert 0.92 < 1 - below - above < 0.98



def test_vectorised_verdicts_equal_compare():
    rng = np.random.default_rng(5)
    tables = np.concatenate([rng.integers(0, 30, size=(300, 4)), [[0, 0, 0, 0], [0, 0, 0, 3], [0, 9, 0, 0]]])
    for margin in (0.0, 0.02, 0.1):
        vectorised = verdicts_of_tables(tables, margin)
        assert vectorised == [compare(PairedTable(*map(int, row)), margin).verdict for row in tables]



@pytest.mark.slow
def test_compare_scenarios_overall_false_alarm_at_most_alpha():
    # identical policies, 21 scenarios of 40 paired episodes with failure rates from 2 to 25 %
    rng = np.random.default_rng(2026)
    reps, rates = 600, np.linspace(0.02, 0.25, 21)
    sims = [simulate_tables(40, p, p, DEFAULT_CORRELATION, reps, rng) for p in rates]
    false_alarms = 0
    for r in range(reps):
        tables = {f"s{i}": PairedTable(*map(int, sims[i][r])) for i in range(len(rates))}
        false_alarms += compare_scenarios(tables, DEFAULT_MARGIN)[1].verdict is Verdict.FAIL
    assert MonteCarloRate(false_alarms, reps).interval()[0] <= DEFAULT_ALPHA



def test_sequential_single_look_is_compare():
    rng = np.random.default_rng(8)
    for row in simulate_tables(300, 0.05, 0.08, DEFAULT_CORRELATION, 200, rng):
        table = PairedTable(*map(int, row))
        test = SequentialTest(DEFAULT_MARGIN, max_episodes=300)
        assert test.update(table) is compare(table, DEFAULT_MARGIN).verdict



def run_sequential(p_candidate: float, repetitions: int, seed: int, looks: int = 5,
                   episodes: int = DOCUMENTED_EPISODES) -> dict:
    """Verdict counts and mean episodes used, batches of episodes / looks, shared-difficulty model."""
    rng = np.random.default_rng(seed)
    cand, base = simulate_paired_outcomes(episodes, DOCUMENTED_BASELINE_RATE, p_candidate, DEFAULT_CORRELATION,
                                          repetitions, rng)
    cells = np.stack([cand & base, cand & ~base, ~cand & base, ~cand & ~base], axis=-1).cumsum(axis=1)
    counts = {verdict: 0 for verdict in Verdict}
    used = 0
    for r in range(repetitions):
        test = SequentialTest(DEFAULT_MARGIN, max_episodes=episodes)
        for k in range(1, looks + 1):
            n = episodes * k // looks
            verdict = test.update(PairedTable(*map(int, cells[r, n - 1])))
            if verdict is not None:
                break
        counts[verdict] += 1
        used += n
    return {"counts": counts, "episodes": used / repetitions}


@pytest.mark.slow
def test_sequential_type_one_error_by_monte_carlo():
    reps = 1500
    result = run_sequential(DOCUMENTED_BASELINE_RATE, reps, seed=17)
    false_alarm = MonteCarloRate(result["counts"][Verdict.FAIL], reps)
    # the exact boundaries spend nearly all of alpha (measured 0.04-0.048), so only the interval
    # is compared with alpha: its lower end must not be above it
    assert false_alarm.interval()[0] <= DEFAULT_ALPHA


@pytest.mark.slow
def test_sequential_false_pass_at_the_margin_by_monte_carlo():
    reps = 1500
    result = run_sequential(DOCUMENTED_BASELINE_RATE + DEFAULT_MARGIN, reps, seed=19)
    false_pass = MonteCarloRate(result["counts"][Verdict.PASS], reps)
    assert false_pass.interval()[0] <= DEFAULT_ALPHA and false_pass.rate <= DEFAULT_ALPHA


@pytest.mark.slow
def test_sequential_keeps_power_and_saves_episodes():
    reps = 1000
    result = run_sequential(DOCUMENTED_BASELINE_RATE + DOCUMENTED_DELTA, reps, seed=23)
    assert result["counts"][Verdict.FAIL] / reps >= 0.75
    assert result["episodes"] < 0.85 * DOCUMENTED_EPISODES
