"""The split sampler (dv2s_gym/mining/sampling/split_sampler.py): a VerifAI sampler over which scenario, one VerifAI
sampler per scenario over its parameters; deterministic, resumable, adaptive."""

from __future__ import annotations

import json
import random

import pytest

from dv2s_gym.mining.cluster import region_of
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.miner import read_records
from mining_helpers import mine
from dv2s_gym.mining.sampling.samplers import SPLIT, SceneSampler, is_adaptive, make_sampler
from dv2s_gym.mining.sampling.space import SceneSpace
from dv2s_gym.mining.sampling.split_sampler import (CHOOSER_TABLE, CHOOSERS, PARAM_SAMPLERS, PARAM_TABLE,
                                                    ScenarioSplitSampler, scenario_dimensions)
from mining_helpers import global_draws, mine_killed_after, seed_globals_and_peek

BRAKES = "highway_lead_vehicle_brakes"
LEFT_TURN = "urban_left_turn_oncoming"
POLICY = "rule?action_noise=0.4"


@pytest.fixture(scope="module")
def space():
    return SceneSpace([BRAKES, LEFT_TURN])


def _drive(sampler, space, draws: int, fails=lambda spec: spec.scenario == LEFT_TURN):
    """Draw and feed one scene at a time; the decoded scenes."""
    specs = []
    for _ in range(draws):
        ((point, info),) = sampler.draw(1)
        spec = space.decode(point)
        specs.append(spec)
        sampler.feed(point, info, -1.0 if fails(spec) else 2.0)
    return specs


def _plain(specs):
    return [(s.scenario, s.point) for s in specs]


@pytest.mark.parametrize("options", [{}, {"chooser": "ucb"}, {"chooser": "epsilon-greedy"}, {"warmup": 2}, {"params": "bandit"}, {"params": "cross-entropy"}])
def test_split_is_deterministic_under_a_seed_resumes_exactly_and_keeps_the_global_generators(space, options):
    before = seed_globals_and_peek(5)
    first = make_sampler(SPLIT, space, 11, options)
    head = _drive(first, space, 15)
    assert global_draws() == before  # nothing drawn from the global generators
    copy = SceneSampler.loads(first.dumps())  # the checkpoint, mid-way
    tail = _drive(first, space, 15)
    assert _plain(_drive(copy, space, 15)) == _plain(tail)  # the restored sampler continues exactly
    random.seed(999)
    again = make_sampler(SPLIT, space, 11, options)
    assert _plain(_drive(again, space, 30)) == _plain(head + tail)
    assert _plain(_drive(make_sampler(SPLIT, space, 12, options), space, 30)) != _plain(head + tail)
    assert is_adaptive(SPLIT)


@pytest.mark.parametrize("options", [{}, {"chooser": "ucb"}])
def test_split_draws_the_scenario_it_is_fed_failures_on_more_often(space, options):
    sampler = make_sampler(SPLIT, space, 3, options)
    learned = _drive(sampler, space, 40)
    late = [s.scenario for s in learned[20:]]
    assert late.count(LEFT_TURN) >= 16, late
    # and the other way round: failures only on the brakes scenario pull the sampler there
    other = _drive(make_sampler(SPLIT, space, 3, options), space, 40, fails=lambda spec: spec.scenario == BRAKES)
    assert [s.scenario for s in other[20:]].count(BRAKES) >= 16


def test_each_scenario_has_its_own_parameter_sampler_over_its_own_parameters(space):
    sampler = make_sampler(SPLIT, space, 0)  # Halton per scenario
    specs = _drive(sampler, space, 60, fails=lambda spec: False)
    turns = [s for s in specs if s.scenario == LEFT_TURN]
    brakes = [s for s in specs if s.scenario == BRAKES]
    dimensions = dict(zip([BRAKES, LEFT_TURN], scenario_dimensions(space)))
    assert dimensions[LEFT_TURN] != dimensions[BRAKES]
    assert len(turns[0].point) == dimensions[LEFT_TURN] and len(brakes[0].point) == dimensions[BRAKES]
    # the left turn's own Halton sequence: its first 18 points cover all 9 cells of the 3 x 3 grid over its
    # first two parameters (a sequence shared with the other scenario would leave gaps there)
    assert len(turns) >= 18 and len({region_of(s.point[:2]) for s in turns[:18]}) == 9
    # unused coordinates of the shared unit box are fixed, not drawn
    ((point, _),) = make_sampler(SPLIT, space, 0).draw(1)
    spec = space.decode(point)
    assert all(u == 0.5 for u in list(point.u)[len(spec.point):])
    # the left turn's points do not depend on what the other scenario was fed
    mixed = _drive(make_sampler(SPLIT, space, 0), space, 60, fails=lambda spec: spec.scenario == BRAKES)
    mixed_turns = [s.point for s in mixed if s.scenario == LEFT_TURN]
    common = min(len(mixed_turns), len(turns))
    assert common >= 5 and mixed_turns[:common] == [s.point for s in turns[:common]]


@pytest.mark.parametrize("chooser", ["cross-entropy", "ucb"])
def test_a_warm_up_tries_every_scenario_first_and_the_chooser_learns_from_it(space, chooser):
    sampler = make_sampler(SPLIT, space, 4, {"warmup": 3, "chooser": chooser})
    first = _drive(sampler, space, 6, fails=lambda spec: spec.scenario == BRAKES)
    assert sorted(s.scenario for s in first) == [BRAKES] * 3 + [LEFT_TURN] * 3
    weights = sampler._sampler.scenario_weights()
    assert weights[space.scenarios.index(BRAKES)] > weights[space.scenarios.index(LEFT_TURN)]


def test_split_options_are_checked(space):
    for bad, match in (({"chooser": "greedy"}, "chooser must be one of cross-entropy, ucb, epsilon-greedy"),
                       ({"params": "sobol"}, "params must be one of halton, random, bandit, cross-entropy"),
                       ({"alpha": 1.0}, "alpha must be between 0 and 1"), ({"buckets": 0}, "buckets must be"),
                       ({"warmup": -1}, "warmup must be a whole number >= 0"), ({"gamma": 1}, "no option 'gamma'")):
        with pytest.raises(MiningError, match=match):
            make_sampler(SPLIT, space, 0, bad)


def test_the_split_sampler_class_refuses_an_unknown_chooser_or_parameter_sampler(space):
    """The public class checks its words too (the command line's check is the sampler options'): a typo is an
    error naming the choices, never some other sampler."""
    assert CHOOSERS == tuple(CHOOSER_TABLE) == ("cross-entropy", "ucb", "epsilon-greedy")
    assert PARAM_SAMPLERS == tuple(PARAM_TABLE) == ("halton", "random", "bandit", "cross-entropy")
    dimensions = scenario_dimensions(space)
    with pytest.raises(MiningError, match=r"chooser must be one of cross-entropy, ucb, epsilon-greedy, not 'ubc'"):
        ScenarioSplitSampler(space.feature_space, dimensions, chooser="ubc")
    with pytest.raises(MiningError, match=r"params must be one of halton, random, bandit, cross-entropy, not 'sobol'"):
        ScenarioSplitSampler(space.feature_space, dimensions, params="sobol")
    for chooser in CHOOSERS:
        assert ScenarioSplitSampler(space.feature_space, dimensions, chooser=chooser).chooser_kind == chooser


RUN = dict(budget=12, sampler=SPLIT, scenarios=[BRAKES, LEFT_TURN], batch=4, seed=7, reference=None,
           env_config={"duration": 3}, progress=False, reports=False)


def _stable(records):
    return [json.dumps(r.to_dict(), sort_keys=True) for r in records]  # episode records, as their file lines


@pytest.mark.slow
def test_a_split_mining_run_killed_mid_way_resumes_to_the_same_records(tmp_path, monkeypatch):
    whole = mine(POLICY, out=tmp_path / "whole", workers=1, **RUN)
    assert json.loads((tmp_path / "whole" / "settings.json").read_text())["schedule"] == "window"
    cut = tmp_path / "cut"
    mine_killed_after(POLICY, cut, 5, monkeypatch, workers=2, **RUN)
    assert len(read_records(cut / "episodes.jsonl")) == 5
    resumed = mine(POLICY, out=cut, workers=2, **RUN)
    assert _stable(resumed.records) == _stable(whole.records)
    assert (cut / "episodes.jsonl").read_bytes().count(b"\n") == 12
    (cut / "sampler.pkl").unlink()  # rebuilt from the records alone, with a larger budget
    longer = mine(POLICY, out=cut, workers=1, **{**RUN, "budget": 14})
    assert _stable(longer.records[:12]) == _stable(whole.records)
    assert [r.to_dict()["scenario"] for r in whole.records] and {r.to_dict()["scenario"] for r in whole.records} <= {BRAKES, LEFT_TURN}
