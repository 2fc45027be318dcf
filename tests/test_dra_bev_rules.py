"""Rules of the bev DRA taught by the external (stock highway-env) evaluation set, tested on their own."""

import numpy as np

from dv2s_gym.pipeline.dra.bev.events import _quick_reversals_dropped
from dv2s_gym.pipeline.dra.bev.language import _clause
from dv2s_gym.pipeline.semantics.text import elements_from_text
from scenario_bank.elements import element_set


def test_quick_out_and_back_lane_changes_are_dropped():
    t = np.arange(50) * 0.2
    assert _quick_reversals_dropped([(9, 2, 3), (13, 3, 2)], t) == []              # 0.8 s apart: noise
    assert _quick_reversals_dropped([(9, 2, 1), (30, 1, 2)], t) == [(9, 2, 1), (30, 1, 2)]  # 4.2 s: real
    assert _quick_reversals_dropped([(9, 2, 1), (12, 1, 0)], t) == [(9, 2, 1), (12, 1, 0)]  # not a reversal
    assert _quick_reversals_dropped([(5, 1, 2), (20, 2, 3), (23, 3, 2)], t) == [(5, 1, 2)]


def _reads(clause: str, ego: str = "The ego car goes straight through a four-way urban intersection"):
    return element_set(elements_from_text(f"{ego} while {clause}. This scene takes place at a four-way urban "
                                          "intersection."))


def test_turning_cars_across_the_path_read_back():
    crossing = _clause({"kind": "car", "actions": {"turn_left"}, "relations": {"crossing_path"}}, 1, "it")
    assert "turns left" in crossing
    assert ("action", "car", "turn_left") in _reads(crossing)
    assert ("action", "car", "go_straight") not in _reads(crossing)
    oncoming = _clause({"kind": "car", "actions": {"turn_left"}, "relations": {"oncoming", "crossing_path"}}, 1, "it")
    got = _reads(oncoming)
    assert {("action", "car", "turn_left"), ("relation", "car", "oncoming", "ego"),
            ("relation", "car", "crossing_path", "ego")} <= got


def test_merge_beside_the_ego_is_not_a_cut_in():
    beside = _clause({"kind": "car", "actions": {"merge"}, "relations": {"right_of"}}, 1, "it")
    got = _reads(beside, "The ego car drives in the left lane of a highway with an on-ramp")
    assert ("action", "car", "merge") in got and ("relation", "car", "right_of", "ego") in got
    assert ("action", "car", "cut_in") not in got
    ahead = _clause({"kind": "car", "actions": {"merge", "cut_in"}, "relations": {"ahead_of", "right_of"}}, 1, "it")
    assert ("action", "car", "cut_in") in _reads(ahead, "The ego car drives in the right lane of a highway with an "
                                                        "on-ramp")
