"""Drift and side collisions read off real simulated traces (scripts of the rules SG, run in the env).

A drift is a vehicle leaving its lane gradually without settling in another one (see
dv2s_gym/pipeline/semantics/trace.py); a lane change that reaches the next lane's centre is none.
"""

import pytest

from dv2s_gym.pipeline.sg.rules import generate_rules
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from sg_helpers import run_script

pytestmark = pytest.mark.slow


def _actions(elements, who):
    return {a for k, a in elements.actions if k == who}


def _simulate(text, seed=0, seconds=10.0):
    return elements_from_trace(run_script(generate_rules(text).script, seconds, seed))


def test_ego_drifting_toward_the_road_edge_drifts_and_does_not_keep_its_lane():
    elements = _simulate("On a two-lane rural road the ego car drifts slowly off the right edge of the road.")
    assert elements.road == "straight_road"
    assert "drift" in _actions(elements, "ego")
    assert not {"keep_lane", "lane_change_left", "lane_change_right", "swerve"} & _actions(elements, "ego")


def test_truck_drifting_into_the_egos_lane_and_back_drifts_without_lane_changes():
    elements = _simulate("On a highway a truck in the lane to the right of the ego drifts into the ego's lane.")
    truck = _actions(elements, "truck")
    assert "drift" in truck
    # the env logged lane changes when its centre crossed the line; during a drift they are none
    assert not {"lane_change_left", "lane_change_right", "cut_in", "swerve", "keep_lane"} & truck


def test_a_real_lane_change_is_no_drift():
    elements = _simulate("On a highway a car in the lane to the left of the ego changes lanes to the left.")
    car = _actions(elements, "car")
    assert "lane_change_left" in car and "drift" not in car


def _checked(text, seed=0):
    """Elements of one run as the SG evaluation runs it (the episode goes on after a collision)."""
    from dv2s_gym.pipeline.convert import check_scenario

    check = check_scenario(generate_rules(text).script, seed=seed, seconds=10.0)
    assert check.ran, check.error
    return check.simulated_elements


def test_a_sideswipe_on_the_highway_is_a_side_collision_and_the_lane_change_stays_one():
    elements = _checked("On a three-lane highway a car in the lane to the left of the ego changes lanes to the right "
                        "into the ego's lane and sideswipes the ego.")
    assert {"collide", "collide_side"} <= _actions(elements, "ego") & _actions(elements, "car")
    assert "collide_head_on" not in _actions(elements, "ego")
    # the crash ends the lane change half-way: it is no drift, and the lane change is kept
    assert "lane_change_right" in _actions(elements, "car") and "drift" not in _actions(elements, "car")


def test_a_t_boned_ego_went_straight_although_the_crash_kept_it_in_the_junction():
    elements = _checked("The ego goes straight through a four-way intersection; a car from the right runs the red "
                        "light and T-bones the ego.")
    ego = _actions(elements, "ego")
    assert {"collide", "collide_side", "go_straight"} <= ego
    assert not {"turn_left", "turn_right"} & ego


def test_a_cyclist_riding_across_the_street_in_front_of_the_ego_crosses():
    text = "On a two-lane street a cyclist suddenly crosses in front of the ego from the right."
    assert "RideAcrossWhenEgoNear(" in generate_rules(text).script
    elements = _checked(text)
    assert "cross" in _actions(elements, "bicycle")
    assert "cross" not in _actions(elements, "ego")


def test_a_pull_out_cut_short_by_a_collision_is_still_a_pull_out():
    elements = _checked("A car reverses out of a parking space on the right side of the street into the path of "
                        "the ego, and the ego strikes its rear corner.")
    car = _actions(elements, "car")
    assert {"collide", "reverse", "pull_out"} <= car
