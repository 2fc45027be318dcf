"""dv2s regress: rliable-style aggregates of the return beside the paired test (context, not the verdict)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from dv2s_gym.regress.records import PairedEpisode
from dv2s_gym.regress.aggregates import (
    interquartile_mean,
    probability_of_improvement,
    return_aggregates,
    stratified_bootstrap,
)


def test_interquartile_mean_is_the_25_percent_trimmed_mean():
    rng = np.random.default_rng(3)
    for size in (4, 7, 40, 101):
        values = rng.standard_cauchy(size)
        assert interquartile_mean(values) == pytest.approx(stats.trim_mean(values, 0.25))
    assert interquartile_mean([1, 2, 3, 1000]) == 2.5  # the outliers do not move it
    assert np.isnan(interquartile_mean([]))


def test_probability_of_improvement_counts_pairs_and_ties_half():
    assert probability_of_improvement({"a": [2, 3]}, {"a": [1, 2]}) == pytest.approx((1 + 0.5 + 1 + 1) / 4)
    # per scenario, then averaged: a scenario with many episodes does not outweigh the others
    assert probability_of_improvement({"a": [5] * 10, "b": [0]}, {"a": [1] * 10, "b": [1]}) == 0.5
    # the Mann-Whitney U statistic over the pairs
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=30), rng.normal(0.5, size=25)
    u = stats.mannwhitneyu(x, y).statistic
    assert probability_of_improvement({"s": x}, {"s": y}) == pytest.approx(u / (30 * 25))


def test_stratified_bootstrap_resamples_within_scenarios():
    rng = np.random.default_rng(5)
    returns = {"easy": (rng.normal(100, 1, 20), rng.normal(100, 1, 20)), "hard": (rng.normal(0, 1, 20),
                                                                            rng.normal(-1, 1, 20))}
    found = stratified_bootstrap(returns, resamples=500, seed=1)
    for stat in (found["return_iqm"]["candidate"], found["return_iqm"]["baseline"], found["probability_of_improvement"]):
        assert stat["low"] <= stat["value"] <= stat["high"]
    # each resample keeps 20 episodes of each scenario: the IQM of a 50/50 mix of 0 and 100 stays near 50
    assert 40 < found["return_iqm"]["candidate"]["low"] and found["return_iqm"]["candidate"]["high"] < 60
    assert found["probability_of_improvement"]["value"] > 0.5


def test_report_carries_the_aggregates_as_context():
    from dv2s_gym.regress.report import _markdown
    from regress_report_data import report_from_json

    rng = np.random.default_rng(6)
    episodes = [{"id": f"s/{k}", "scenario": "s", "seed": k,
                 "candidate": {"failed": False, "episode_return": float(rng.normal(2))},
                 "baseline": {"failed": False, "episode_return": float(rng.normal(0))}} for k in range(30)]
    bank = {"path": "x", "version": "v", "scenarios": ["s"], "hashes": {"s": "h"}}
    report = report_from_json(bank=bank, settings={"episodes": 30, "seed": 0, "margin": 0.02, "alpha": 0.05, "failure": ["collision", "off_road"]},
                              candidate={"spec": "new"}, baseline={"spec": "old"}, episodes=episodes)
    poi = report.to_dict()["aggregates"]["probability_of_improvement"]
    assert poi["value"] > 0.8 and poi["low"] <= poi["value"] <= poi["high"]
    assert "probability of improvement" in _markdown(report) and "the verdict is the paired failure test" in _markdown(report)
    alone = report_from_json(bank=bank, settings={"episodes": 30, "seed": 0, "margin": 0.02, "alpha": 0.05, "failure": ["collision", "off_road"]},
                             candidate={"spec": "new"}, baseline=None, episodes=[dict(e, baseline=None) for e in episodes])
    assert alone.aggregates is None and return_aggregates([PairedEpisode.from_dict(dict(e, baseline=None))
                                                                  for e in episodes]) is None
