"""dv2s regress: runs sized by power (--mde, --power) and the power every report states."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from dv2s_gym.regress import RegressError
from regress_call import run_regression
from dv2s_gym.regress.power import (
    ASSUMED_BASELINE_RATE,
    discordance,
    mcnemar_power,
    plan_episodes,
    run_power,
    scenario_level,
    smallest_detectable,
)

SCENARIO = "highway_lead_vehicle_brakes"


def test_exact_power_matches_a_simulation_of_the_test():
    n, psi, delta, level = 40, 0.3, 0.3, 0.0012
    rng = np.random.default_rng(7)
    discordant = rng.binomial(n, psi, 20000)
    candidate_only = rng.binomial(discordant, (psi + delta) / (2 * psi))
    p = np.where(discordant > 0, stats.binom.sf(candidate_only - 1, np.maximum(discordant, 1), 0.5), 1.0)
    assert mcnemar_power(n, psi, delta, level) == pytest.approx(np.mean(p <= level), abs=0.015)
    assert mcnemar_power(n, psi, 0.0, level) == 0.0


def test_discordance_follows_the_shared_difficulty_model():
    # latent correlation 0.5: both fail with the bivariate normal probability beyond their two thresholds
    both = stats.multivariate_normal.cdf([stats.norm.ppf(0.05), stats.norm.ppf(0.08)], mean=[0, 0],
                                         cov=[[1, 0.5], [0.5, 1]], abseps=1e-10, releps=1e-10)
    assert discordance(0.05, 0.03) == pytest.approx(0.05 + 0.08 - 2 * both, rel=1e-6)
    assert discordance(0.0, 0.3) == pytest.approx(0.3, abs=1e-3)  # a clean baseline: every failure is new


def test_plan_gives_the_smallest_run_that_reaches_the_power():
    names = [f"s{i}" for i in range(21)]
    plan = plan_episodes(names, mde=0.3, power=0.8)
    n, level = plan.episodes, scenario_level(0.05, 21)
    assert plan.level == pytest.approx(level)
    psi = discordance(ASSUMED_BASELINE_RATE, 0.3)
    assert mcnemar_power(n, psi, 0.3, level) >= 0.8 > mcnemar_power(n - 1, psi, 0.3, level)
    assert "assumed baseline failure rate of 5%" in plan.assumption
    assert set(plan.per_scenario) == set(names) and max(v.episodes for v in plan.per_scenario.values()) == n
    # fewer scenarios: a higher level each, fewer episodes; a measured clean baseline: fewer too
    assert plan_episodes(names[:2]).episodes < n
    measured = plan_episodes(names, baseline_rates={name: 0.0 for name in names})
    assert measured.episodes < n and "measured failure rate" in measured.assumption
    with pytest.raises(ValueError, match="--mde"):
        plan_episodes(names, mde=1.5)
    with pytest.raises(ValueError, match="larger --mde or a lower --power"):
        plan_episodes(names, mde=0.001, power=0.99)


def test_run_power_states_power_per_scenario_and_pooled():
    power = run_power({"a": 40, "b": 40}, {"a": 0.0, "b": None}, margin=0.02, alpha=0.05, mde=0.3)
    a, pooled = power.per_scenario["a"], power.pooled
    assert a.n == 40 and pooled.n == 80 and power.power == 0.8 and power.mde == 0.3
    assert 0 <= a.at_margin < a.at_mde <= 1
    assert a.at_mde == pytest.approx(mcnemar_power(40, discordance(a.baseline_rate, 0.3), 0.3,
                                                   scenario_level(0.05, 2)))
    detectable = a.detectable
    assert mcnemar_power(40, discordance(a.baseline_rate, detectable), detectable, a.level) >= 0.8
    assert smallest_detectable(40, a.baseline_rate, 0.8, a.level) == detectable
    assert pooled.level == pytest.approx(0.025) and pooled.at_mde is None
    assert power.per_scenario["b"].baseline_rate == ASSUMED_BASELINE_RATE
    # the JSON object a report holds: every estimate's field, null where undefined
    assert power.to_dict()["pooled"] == {"n": 80, "baseline_rate": pooled.baseline_rate, "level": pooled.level,
                                         "at_margin": pooled.at_margin, "at_mde": None,
                                         "detectable": pooled.detectable}


@pytest.mark.slow
def test_a_run_without_episodes_is_sized_by_power_and_states_it(tmp_path):
    report = run_regression("rule", "rule", scenarios=[SCENARIO], mde=0.9, power=0.5, workers=1, out_dir=tmp_path,
                            env_config={"duration": 2}, stall_seconds=1, progress=False)
    plan = report.settings.plan
    assert (plan.mde, plan.power, plan.per_scenario, plan.note) == (0.9, 0.5, None, None)
    expected = plan_episodes([SCENARIO], mde=0.9, power=0.5).episodes
    assert report.settings.episodes == plan.episodes == plan.planned == expected == len(report.episodes)
    stated = report.power.per_scenario[SCENARIO]
    assert stated.n == expected and stated.at_mde is not None
    from dv2s_gym.regress.report import format_summary

    text = format_summary(report)
    assert "power per scenario" in text and "power pooled" in text and "power model:" in text
    with pytest.raises(RegressError, match="not both"):
        run_regression("rule", "rule", scenarios=[SCENARIO], episodes=3, mde=0.3, out_dir=tmp_path / "x",
                       progress=False)
