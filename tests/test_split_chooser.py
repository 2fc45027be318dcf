"""The forgetting scenario chooser (dv2s_gym/mining/chooser.py) and the split sampler's forget/patience options:
a scenario that stops yielding failures loses probability; failures update it exactly like VerifAI's sampler."""

from __future__ import annotations

import random

import numpy as np
import pytest
from verifai.features import DiscreteBox
from verifai.samplers.cross_entropy import DiscreteCrossEntropySampler

from dv2s_gym.mining.chooser import ForgetfulCrossEntropySampler, LeaveSettings
from dv2s_gym.mining.cluster import region_of
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.samplers import SPLIT, SceneSampler, make_sampler
from dv2s_gym.mining.space import SceneSpace
from dv2s_gym.mining.split_sampler import scenario_dimensions

BRAKES = "highway_lead_vehicle_brakes"
LEFT_TURN = "urban_left_turn_oncoming"
STOPPED = "highway_lead_vehicle_stopped"


@pytest.fixture(scope="module")
def space():
    return SceneSpace([BRAKES, LEFT_TURN])


def _chooser(cells=None, **leave):
    return ForgetfulCrossEntropySampler(DiscreteBox([0, 3]), alpha=0.9, thres=0.0, leave=LeaveSettings(**leave),
                                        cells=cells)


def test_non_failures_on_one_scenario_move_its_probability_to_the_others():
    chooser = _chooser(forget=0.1)
    before = chooser.dist[0].copy()
    history = [float(before[2])]
    for _ in range(5):  # repeats (fed as easy scenes under novelty feedback) on scenario 2
        chooser.update((2,), None, 9.0)
        history.append(float(chooser.dist[0][2]))
    assert all(b < a for a, b in zip(history, history[1:]))  # falls with every non-novel outcome
    assert history[-1] == pytest.approx(0.25 * 0.9 ** 5)
    others = [float(chooser.dist[0][j]) for j in (0, 1, 3)]
    assert others[0] == pytest.approx(others[1]) and others[1] == pytest.approx(others[2]) and others[0] > 0.25
    assert float(chooser.dist[0].sum()) == pytest.approx(1.0)
    plain = DiscreteCrossEntropySampler(DiscreteBox([0, 3]), alpha=0.9, thres=0.0)
    plain.update((2,), None, 9.0)
    assert list(plain.dist[0]) == [0.25] * 4  # VerifAI's own sampler never moves away


def test_failures_update_exactly_like_verifai_and_reset_the_stagnation_count():
    ours, verifai = _chooser(forget=0.0, patience=3), DiscreteCrossEntropySampler(DiscreteBox([0, 3]), 0.9, 0.0)
    for index in (1, 1, 3, 1):
        ours.update((index,), None, -1.0)
        verifai.update((index,), None, -1.0)
    assert np.allclose(ours.dist[0], verifai.dist[0])
    assert ours.dry[1] == 0 and ours.restarts == 0


def test_a_scenario_without_failures_for_patience_draws_is_cut_to_the_floor():
    chooser = _chooser(patience=3, floor=0.5)
    for _ in range(6):
        chooser.update((0,), None, -1.0)  # scenario 0 locks on: 0.25 -> about 0.6
    high = float(chooser.dist[0][0])
    assert high > 0.55
    chooser.update((0,), None, 9.0)
    chooser.update((0,), None, 9.0)
    assert float(chooser.dist[0][0]) == pytest.approx(high) and chooser.restarts == 0  # patience not yet spent
    chooser.update((0,), None, 2.0)  # the third draw in a row without a failure
    assert float(chooser.dist[0][0]) == pytest.approx(0.5 / 4) and chooser.restarts == 1
    assert float(chooser.dist[0].sum()) == pytest.approx(1.0)
    assert chooser.dry[0] == 0  # counts again from here


def _drive(sampler, space, draws, fails):
    specs = []
    for step in range(draws):
        ((point, info),) = sampler.draw(1)
        spec = space.decode(point)
        specs.append(spec)
        sampler.feed(point, info, -1.0 if fails(step, spec) else 9.0)
    return specs


@pytest.mark.slow
def test_the_split_sampler_leaves_a_scenario_that_stopped_yielding(space):
    def early(step, spec):  # the left turn yields new failures for the first 15 draws, then nothing new
        return spec.scenario == LEFT_TURN and step < 15

    locked = _drive(make_sampler(SPLIT, space, 2, {"forget": 0.0, "patience": 0}), space, 60, early)
    left = _drive(make_sampler(SPLIT, space, 2, {"forget": 0.1, "patience": 8}), space, 60, early)
    late_locked = [s.scenario for s in locked[30:]].count(LEFT_TURN)
    late_left = [s.scenario for s in left[30:]].count(LEFT_TURN)
    assert late_locked >= 24  # VerifAI's chooser stays on it
    assert late_left <= 18 and late_left < late_locked


@pytest.mark.parametrize("options", [{"forget": 0.1}, {"patience": 5}, {"forget": 0.05, "patience": 4, "floor": 0.2},
                                     {"avoid": 9, "capacity": 1.0}])
def test_forgetting_split_is_deterministic_and_resumes_exactly(space, options):
    def half(step, spec):
        return spec.scenario == LEFT_TURN and step % 2 == 0

    random.seed(1)
    first = make_sampler(SPLIT, space, 11, options)
    head = _drive(first, space, 20, half)
    copy = SceneSampler.loads(first.dumps())
    tail = _drive(first, space, 20, half)
    assert [(s.scenario, s.point) for s in _drive(copy, space, 20, half)] == [(s.scenario, s.point) for s in tail]
    random.seed(2)
    again = _drive(make_sampler(SPLIT, space, 11, options), space, 40, half)
    assert [(s.scenario, s.point) for s in again] == [(s.scenario, s.point) for s in head + tail]


def test_forgetting_options_are_checked(space):
    for bad, match in (({"forget": 1.0}, "forget must be in"), ({"capacity": -1}, "capacity must be >= 0"), ({"forget": -0.1}, "forget must be in"),
                       ({"patience": -1}, "patience must be a whole number"),
                       ({"patience": 2.5}, "patience must be a whole number"), ({"avoid": -2}, "avoid must be a whole number"), ({"floor": 2}, "floor must be in"),
                       ({"chooser": "ucb", "forget": 0.1}, "need chooser cross-entropy")):
        with pytest.raises(MiningError, match=match):
            make_sampler(SPLIT, space, 0, bad)


def test_a_scenario_drawn_past_its_capacity_keeps_only_what_new_failures_give_it():
    chooser = _chooser(capacity=2.0, cells=[1, 3, 81, 81], floor=0.5)  # index 1: exhausted after 6 draws
    for _ in range(5):
        chooser.update((1,), None, -1.0)  # five new failures: its probability rises
    risen = float(chooser.dist[0][1])
    assert risen > 0.5 and chooser.restarts == 0
    chooser.update((1,), None, 9.0)  # sixth draw, nothing new: exhausted, cut to the floor
    assert float(chooser.dist[0][1]) == pytest.approx(0.5 / 4) and chooser.restarts == 1
    chooser.update((1,), None, -1.0)  # a new failure still counts like VerifAI's update
    assert float(chooser.dist[0][1]) == pytest.approx(0.9 * 0.5 / 4 + 0.1)
    chooser.update((1,), None, 9.0)  # and the next non-failure cuts it again
    assert float(chooser.dist[0][1]) == pytest.approx(0.5 / 4)
    for _ in range(6):
        chooser.update((2,), None, 9.0)  # 81 cells: far from exhausted, untouched
    assert float(chooser.dist[0][2]) > 0.5 / 4 and chooser.restarts == 2
    assert float(chooser.dist[0].sum()) == pytest.approx(1.0)


def test_the_split_sampler_gives_the_chooser_each_scenarios_cells(space):
    sampler = make_sampler(SPLIT, space, 0, {"capacity": 1.5})._sampler
    assert list(sampler.chooser.cells) == [3 ** d for d in scenario_dimensions(space)]  # 3 bins per parameter
    assert type(make_sampler(SPLIT, space, 0, {"forget": 0.0, "patience": 0, "capacity": 0.0})._sampler.chooser) \
        is DiscreteCrossEntropySampler  # all off: VerifAI's own chooser, the old behaviour


def test_avoid_draws_past_the_cells_where_a_scenario_already_failed():
    small = SceneSpace([BRAKES, STOPPED])  # the stopped lead: 3 parameters, 27 cells

    def turns(options, draws=80):
        sampler = make_sampler(SPLIT, small, 5, {"forget": 0.0, "patience": 0, "capacity": 0.0, **options})
        cells = []
        for _ in range(draws):
            ((point, info),) = sampler.draw(1)
            spec = small.decode(point)
            if spec.scenario == STOPPED:
                cell = region_of(spec.point)
                failed = cell.startswith("r0.")  # fails in the 9 cells of its first parameter's low third
                cells.append((cell, failed))
            else:
                failed = False
            sampler.feed(point, info, -1.0 if failed else 9.0)
        return cells

    plain, avoiding = turns({"avoid": 0}), turns({"avoid": 9})
    plain_repeats = sum(failed for _, failed in plain) - len({c for c, failed in plain if failed})
    avoiding_repeats = sum(failed for _, failed in avoiding) - len({c for c, failed in avoiding if failed})
    assert plain_repeats >= 2  # Halton comes back to the failing cells
    assert avoiding_repeats == 0 and len({c for c, failed in avoiding if failed}) >= 2
