"""``novelty-bandit``'s ``cover``: every scenario gets its scenes before the scores rank the scenarios."""

from __future__ import annotations

import pytest
from verifai.features import Box, DiscreteBox, Feature, FeatureSpace

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.sampling.samplers import NOVELTY, make_sampler, sampler_params

SCENARIOS = 6


def _draws(cover: int, count: int, seed: int = 0, explore: float = 1e-6):
    """Scenario indices and recorded scenario densities of ``count`` draws; scenario 0 fails every time and each of
    its failures is fed as a new one right away (the strongest pull toward one scenario)."""
    space = FeatureSpace({"scenario": Feature(DiscreteBox([0, SCENARIOS - 1])), "u": Feature(Box([0.0, 1.0]))})
    sampler = make_sampler(NOVELTY, space, seed, {"cover": cover, "explore": explore})
    drawn, densities = [], []
    for index in range(count):
        ((point, info),) = sampler.draw(1)
        drawn.append(int(point.scenario[0]))
        densities.append(sampler.proposal(index)["scenario"])
        sampler.feed(point, info, -1.0 if drawn[-1] == 0 else 1.0)
    return drawn, densities


def test_cover_draws_every_scenario_before_the_scores_rank_them():
    for seed in range(5):
        drawn, densities = _draws(cover=1, count=SCENARIOS, seed=seed)
        assert sorted(drawn) == list(range(SCENARIOS))  # a permutation: no scenario twice before each had one
        for index, density in enumerate(densities):  # the mixture's density over the scenarios still short
            assert density == pytest.approx(1e-6 / SCENARIOS + (1 - 1e-6) / (SCENARIOS - index))
        twice, _ = _draws(cover=2, count=2 * SCENARIOS, seed=seed)
        assert all(twice.count(s) == 2 for s in range(SCENARIOS))


def test_without_cover_a_failing_scenario_is_drawn_again_before_the_others_are_tried():
    checked = 0
    for seed in range(5):
        drawn, _ = _draws(cover=0, count=SCENARIOS, seed=seed)
        first = drawn.index(0) if 0 in drawn else SCENARIOS
        if first < SCENARIOS - 1:  # its failure outranks an untried scenario (3/4 against 2/3)
            assert drawn[first + 1] == 0
            checked += 1
        covered, _ = _draws(cover=1, count=3 * SCENARIOS, seed=seed)
        assert covered[SCENARIOS:].count(0) >= SCENARIOS  # once covered, the scores rank: the failing one wins
    assert checked >= 3


@pytest.mark.parametrize("bad", [-1, 1.5, True, "two"])
def test_a_bad_cover_is_refused_naming_the_option(bad):
    with pytest.raises(MiningError, match="cover"):
        sampler_params(NOVELTY, {"cover": bad})


def test_cover_is_one_by_default():
    assert sampler_params(NOVELTY, {})["cover"] == 1
