"""The failure-rate estimate of a mining run (``dv2s_gym.mining.sampling.rate``): importance weights from the proposal
density each scene was drawn with, on synthetic cases where the true rate is known."""

from __future__ import annotations

import numpy as np
import pytest

from dv2s_gym.mining.sampling.rate import failure_rate, weighted_rate
from scenario_bank.records import EpisodeRecord


def test_an_unfair_proposal_is_reweighted_to_the_true_rate():
    # the scenario's own distribution: u uniform on [0, 1], failing below 0.1 (true rate 0.1); the proposal draws
    # half of its points in the failure region (density 5 there, 0.5 / 0.9 elsewhere)
    rng = np.random.default_rng(3)
    n = 4000
    inside = rng.random(n) < 0.5
    u = np.where(inside, rng.uniform(0.0, 0.1, n), rng.uniform(0.1, 1.0, n))
    density = np.where(u < 0.1, 5.0, 0.5 / 0.9)
    outcomes = (u < 0.1).astype(float)
    estimate = weighted_rate(list(outcomes), list(1.0 / density))
    assert outcomes.mean() == pytest.approx(0.5, abs=0.03)  # what the sampler saw
    assert estimate.low <= 0.1 <= estimate.high
    assert estimate.value == pytest.approx(0.1, abs=0.01)
    assert estimate.high - estimate.low < 0.03
    # drawing the failure region more often could be worth more than n uniform draws, but the interval never
    # claims more than Kish's effective sample size of the weights (a rare small-weight failure would fake it)
    assert estimate.ess <= n
    assert estimate.failures == int(outcomes.sum()) and estimate.n == n


def test_a_proposal_that_avoids_the_failure_region_is_worth_fewer_draws():
    # the same target, drawn with 1 % of the points in the failure region (density 0.1 there, 0.99 / 0.9 elsewhere)
    rng = np.random.default_rng(4)
    n = 4000
    inside = rng.random(n) < 0.01
    u = np.where(inside, rng.uniform(0.0, 0.1, n), rng.uniform(0.1, 1.0, n))
    density = np.where(u < 0.1, 0.1, 0.99 / 0.9)
    estimate = weighted_rate(list((u < 0.1).astype(float)), list(1.0 / density))
    assert estimate.low <= 0.1 <= estimate.high
    assert estimate.ess < n / 5


def test_equal_weights_give_the_plain_rate_and_its_wilson_interval():
    from dv2s_gym.regress.stats import wilson_interval

    estimate = weighted_rate([1, 0, 0, 1, 0, 0, 0, 0], [1.0] * 8)
    assert estimate.value == 0.25 and estimate.ess == pytest.approx(8)
    assert (estimate.low, estimate.high) == pytest.approx(wilson_interval(2, 8))


def test_no_failure_still_has_an_upper_bound():
    estimate = weighted_rate([0] * 50, [1.0] * 50)
    assert estimate.value == 0.0 and estimate.low == 0.0 and 0.0 < estimate.high < 0.1


def test_outcomes_and_weights_must_pair_up():
    with pytest.raises(ValueError, match="one weight per outcome"):
        weighted_rate([1, 0], [1.0])


def _cross_entropy_run(dimensions: int, draws: int, seed: int):
    """Records of VerifAI's cross-entropy sampler mining two synthetic scenarios: scenario 0 fails where its first
    parameter is below 0.2 (true rate 0.2), scenario 1 never (0); each with ``dimensions`` parameters."""
    from verifai.features import Box, DiscreteBox, Feature, FeatureSpace

    from dv2s_gym.mining.sampling.samplers import make_sampler, scene_proposal

    space = FeatureSpace({"scenario": Feature(DiscreteBox([0, 1])),
                          "u": Feature(Box(*[[0.0, 1.0]] * dimensions))})
    sampler = make_sampler("cross-entropy", space, seed)
    records = []
    for index in range(draws):
        ((point, info),) = sampler.draw(1)
        scenario, u = int(point.scenario[0]), [float(x) for x in point.u]
        failed = scenario == 0 and u[0] < 0.2
        sampler.feed(point, info, -1.0 if failed else 1.0)
        records.append(EpisodeRecord(index=index, scenario=f"s{scenario}", seed=index, sampler="cross-entropy",
                                     failure={"type": "collision"} if failed else None,
                                     proposal=scene_proposal(sampler.proposal(index), dimensions)))
    return records


@pytest.mark.slow
def test_the_cross_entropy_sampler_s_densities_recover_the_true_rates():
    """The sampler learns to draw the failure region (its first bucket of five); the densities recorded at each
    draw bring the estimate back to the rates under the scenarios' own (uniform) distributions. Over six seeds
    the 95 % intervals cover the true rates (all but one allowed: a miss has 5 % chance per seed) and the
    estimates average to them."""
    covered_s0 = covered_overall = 0
    values = []
    for seed in range(6):
        records = _cross_entropy_run(dimensions=1, draws=500, seed=seed)
        drawn = [r for r in records if r.scenario == "s0"]
        assert sum(1 for r in drawn if r.failure) / len(drawn) > 0.5  # what the sampler saw
        rate = failure_rate(records, scenarios=["s0", "s1"], sampler="cross-entropy")
        assert rate.available and rate.scenarios["s1"].value == 0.0
        s0, overall = rate.scenarios["s0"], rate.overall
        covered_s0 += s0.low <= 0.2 <= s0.high
        covered_overall += overall.low <= 0.1 <= overall.high
        values.append(s0.value)
    assert covered_s0 >= 5 and covered_overall >= 5
    assert sum(values) / len(values) == pytest.approx(0.2, abs=0.005)


@pytest.mark.slow
def test_a_collapsed_proposal_is_flagged():
    """Along a parameter that does not matter the sampler also collapses onto one bucket and stops drawing the
    rest, so the estimate misses most of the failures: the report must say so."""
    records = _cross_entropy_run(dimensions=2, draws=1000, seed=11)
    rate = failure_rate(records, scenarios=["s0", "s1"], sampler="cross-entropy")
    assert rate.scenarios["s0"].high < 0.2  # the estimate is far too low...
    assert rate.collapsed is True  # ...and flagged
    uniform = [r.replace(sampler="random", proposal=None) for r in records[:20]]
    assert failure_rate(uniform, sampler="random").collapsed is False


def test_a_sampler_without_densities_gives_no_estimate():
    records = [EpisodeRecord(index=0, scenario="a", seed=0, failure=None, sampler="bandit", proposal=None)]
    rate = failure_rate(records, sampler="bandit")
    assert rate.available is False and rate.overall is None


def _novelty_bandit_run(draws: int, seed: int, window: int = 4):
    """Records of the novelty-bandit sampler mining three synthetic scenarios, fed back ``window`` draws late (as the
    miner's window does): scenario 0 fails where its first parameter is below 0.2 (true rate 0.2), scenario 1 where
    both are above 0.7 (0.09), scenario 2 never; every failure is fed as a new one, so the sampler keeps drawing the
    failing scenarios."""
    from verifai.features import Box, DiscreteBox, Feature, FeatureSpace

    from dv2s_gym.mining.sampling.samplers import NOVELTY, make_sampler, scene_proposal

    space = FeatureSpace({"scenario": Feature(DiscreteBox([0, 2])), "u": Feature(Box(*[[0.0, 1.0]] * 2))})
    sampler = make_sampler(NOVELTY, space, seed)
    records, pending = [], []
    for index in range(draws):
        ((point, info),) = sampler.draw(1)
        scenario, u = int(point.scenario[0]), [float(x) for x in point.u]
        failed = (scenario == 0 and u[0] < 0.2) or (scenario == 1 and u[0] > 0.7 and u[1] > 0.7)
        pending.append((point, info, -1.0 if failed else 1.0))
        if len(pending) > window:
            sampler.feed(*pending.pop(0))
        records.append(EpisodeRecord(index=index, scenario=f"s{scenario}", seed=index, sampler=NOVELTY,
                                     failure={"type": "collision"} if failed else None,
                                     proposal=scene_proposal(sampler.proposal(index), 2)))
    return records


@pytest.mark.slow
def test_the_novelty_bandit_s_densities_recover_the_true_rates():
    """The sampler draws the failing scenarios far more often than uniform; its recorded densities (a mixture with
    uniform: every weight at most 1 / explore = 5) bring the estimates back to the true rates under the scenarios'
    own distributions (overall (0.2 + 0.09 + 0) / 3). Over eight seeds the 95 % intervals cover the truth (all but
    one allowed) and the overall estimates average to it."""
    truth = (0.2 + 0.09 + 0.0) / 3
    covered = 0
    values = []
    for seed in range(8):
        records = _novelty_bandit_run(draws=400, seed=seed)
        shares = {name: sum(1 for r in records if r.scenario == name) / len(records) for name in ("s0", "s1", "s2")}
        assert shares["s2"] < 0.2 < shares["s0"]  # not uniform: the scenario that never fails is drawn least
        assert min(r.proposal["scenario"] for r in records) == pytest.approx(0.2 / 3)  # never below explore / S
        assert all(r.proposal["params"] == 1.0 and r.proposal["floor"] >= 0.2 - 1e-9 for r in records)
        rate = failure_rate(records, scenarios=["s0", "s1", "s2"], sampler="novelty-bandit")
        assert rate.available and not rate.collapsed
        assert rate.scenarios["s2"].value == 0.0
        overall = rate.overall
        covered += overall.low <= truth <= overall.high
        values.append(overall.value)
    assert covered >= 7
    assert sum(values) / len(values) == pytest.approx(truth, abs=0.01)


def test_an_estimate_pushed_past_one_by_heavy_weights_keeps_a_wide_interval():
    """A short adaptive run of a policy that fails often: the few uniform draws (weight 5) all failed, the many
    draws of the favoured scenario (weight 0.1) mostly too; the plain estimate passes 1 and is shown capped, but
    its interval must say how little 60 such episodes tell (not [0.94, 1] as 60 equal-weight failures would)."""
    weights = [5.0] * 12 + [0.1] * 48
    outcomes = [1] * 12 + [1] * 40 + [0] * 8
    estimate = weighted_rate(outcomes, weights)
    assert estimate.raw > 1.0 and estimate.value == 1.0 and estimate.high == 1.0
    assert estimate.low < 0.75
    assert estimate.ess < 20  # Kish's: a few heavy weights are worth a few draws


def test_the_effective_sample_size_never_exceeds_kish_s_or_the_episode_count():
    """One failure with a small weight among 99 clean draws: p (1 - p) / variance would claim about 10,000
    effective episodes and an interval up to 0.06 %; capped at Kish's, the interval is about as wide as 99 clean
    draws'."""
    one = weighted_rate([1.0] + [0.0] * 99, [0.01] + [1.0] * 99)
    kish = (0.01 + 99) ** 2 / (0.01 ** 2 + 99)
    assert one.ess == pytest.approx(kish) and one.ess <= one.n
    assert one.high > 0.03


def test_the_interval_covers_the_truth_when_the_proposal_piles_onto_one_small_failing_region():
    """A proposal drawing a fifth of its scenes in a tiny failing region while another, larger one fails too: the
    nominal 95 % interval covers the true rate in at least 93 % of 600 runs (it covered about 78 % before its
    effective sample size was capped)."""
    a, b, mix, n = 1e-4, 0.02, 0.2, 100
    rng = np.random.default_rng(12345)
    covered, runs = 0, 600
    for _ in range(runs):
        x = np.where(rng.random(n) < mix, rng.random(n) * a, rng.random(n))
        density = (1 - mix) + mix * (x < a) / a
        y = ((x < a) | ((x >= 0.5) & (x < 0.5 + b))).astype(float)
        est = weighted_rate(list(y), list(1.0 / density))
        covered += est.low <= a + b <= est.high
        assert est.ess <= n + 1e-9
    assert covered / runs >= 0.93
