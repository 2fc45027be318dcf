"""Rules-SG composition of events: a stop at a junction that waits for the crossing vehicle and then goes on,
and the warnings about what the script does not build."""

import numpy as np
import pytest

from dv2s_gym.pipeline.sg.rules import generate_rules, unshown_warnings
from dv2s_gym.pipeline.semantics.trace import map_view, elements_from_trace
from sg_helpers import run_script

STOP_THEN_STRAIGHT = ("At a four-way intersection the ego stops at the stop sign for a car crossing from the right, "
                      "then goes straight.")


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_the_ego_stops_for_the_crossing_car_then_goes_straight_after_it_has_passed(seed):
    result = generate_rules(STOP_THEN_STRAIGHT)
    assert "StopForConflict(" in result.script
    trace = run_script(result.script, 10.0, seed)
    elements = elements_from_trace(trace)
    ego = {a for k, a in elements.actions if k == "ego"}
    assert {"stop", "go_straight"} <= ego
    assert ("car", "go_straight") in {tuple(a) for a in elements.actions}
    # it waited: the ego enters the junction only after the car has left it
    view = map_view(trace)
    track = {name: np.array([step[name] for step in trace.states]) for name in ("ego", "Car1")}
    inside = {name: np.flatnonzero(view.in_junction(t)) for name, t in track.items()}
    assert inside["ego"].size and inside["Car1"].size and inside["ego"][0] > inside["Car1"][-1]


def test_a_stop_without_anything_to_wait_for_keeps_the_timed_brake():
    assert "StopForConflict(" not in generate_rules("On a highway the car ahead of the ego stops suddenly.").script


def test_every_parsed_element_the_script_does_not_build_is_warned_with_its_words():
    # a deer is an obstacle: it cannot cross, so neither the crossing nor its relations are built
    result = generate_rules("On a two-lane rural road a deer runs across the road from the right in front of the ego.")
    warned = [w for w in result.warnings if w.startswith("not built:")]
    assert any("action obstacle cross" in w and "runs across" in w for w in warned), result.warnings
    assert not any("ego" in w.split("(")[0] and "action ego" in w for w in warned)


def test_no_other_vehicles_is_read_and_said():
    result = generate_rules("The ego car drifts off the right edge of an empty rural road; there are no other vehicles.")
    assert any(w.startswith("read 'no other vehicles'") for w in result.warnings), result.warnings


def test_a_typed_collision_is_meant_and_checked_against_the_run():
    result = generate_rules("On a highway a car in the lane to the left of the ego changes lanes to the right and "
                            "sideswipes the ego.")
    assert ("ego", "collide_side") in result.elements.actions
    shown = {"road": "highway", "participants": ["ego", "car"], "actions": [["ego", "collide"], ["car", "collide"]],
             "relations": []}
    missing = unshown_warnings(result.elements, shown)
    assert "not shown in the simulated run: action ego collide side" in missing
    assert not any(w.endswith("action ego collide") for w in missing)


@pytest.mark.slow
def test_a_parked_ego_backing_out_collides_with_the_side_of_the_car_coming_from_behind():
    from dv2s_gym.pipeline.convert import check_scenario

    result = generate_rules("The ego reverses out of a parking space on a street and backs into the side of a car "
                            "driving along the street behind it.")
    assert "BackUpThenPullOutInto(" in result.script
    hits = 0
    for seed in (0, 1):
        check = check_scenario(result.script, seed=seed, seconds=10.0)
        actions = {tuple(a) for a in check.simulated_elements.actions}
        assert ("ego", "reverse") in actions
        hits += {("ego", "collide_side"), ("car", "collide_side")} <= actions
    assert hits == 2


@pytest.mark.slow
def test_an_ego_that_stops_then_turns_left_into_an_oncoming_car_is_hit_on_its_side():
    from dv2s_gym.pipeline.convert import check_scenario

    result = generate_rules("The ego waits at a four-way intersection, then turns left, and an oncoming car going "
                            "straight hits the right side of the ego.")
    assert "StopThenGoInto(" in result.script
    for seed in (0, 1):
        check = check_scenario(result.script, seed=seed, seconds=10.0)
        actions = {tuple(a) for a in check.simulated_elements.actions}
        assert {("ego", "stop"), ("ego", "collide_side"), ("car", "collide_side"), ("car", "go_straight")} <= actions


@pytest.mark.parametrize("text, who, side", [
    ("The ego veers into the lane to its left after a tyre blow-out.", "ego", "left"),
    ("The ego car drifts slowly towards the road edge on the right.", "ego", "right"),
    ("An oncoming truck drifts across the centre line.", "truck", "left"),
    ("The ego changes lanes to the right, overshoots the lane and runs onto the shoulder.", "ego", None),
    ("A truck in the right lane drifts into the ego's lane.", "truck", None),
])
def test_drift_phrases_and_their_side(text, who, side):
    from dv2s_gym.pipeline.semantics.text import parse_description

    entity = next(e for e in parse_description(text).entities if e.kind == who)
    assert entity.has("drift")
    assert entity.detail("drift").get("side") == side


def test_pulling_onto_the_shoulder_is_no_drift():
    from dv2s_gym.pipeline.semantics.text import parse_description

    car = next(e for e in parse_description("The car ahead pulls onto the shoulder and stops.").entities
               if e.kind == "car")
    assert not car.has("drift") and car.has("stop")


def test_an_action_read_onto_a_static_object_is_an_unplaced_phrase():
    from dv2s_gym.pipeline.semantics.text import parse_description

    parsed = parse_description("After a tyre blow-out the ego veers into the lane to its left.")
    assert parsed.unplaced, "the clause whose action went to the tyre must be warned about"


def test_generation_notes_what_the_simulated_run_did_not_show():
    from dv2s_gym.pipeline.stages import Generation

    meant = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "cut_in"], ["ego", "brake"]],
             "relations": [["car", "left_of", "ego"]]}
    shown = {"road": "highway", "participants": ["ego", "car"], "actions": [["ego", "brake"]], "relations": []}
    generation = Generation("script", "rules", warnings=["could not place: 'x'"], intended_elements=meant)
    new = generation.note_simulated(shown)
    assert new == ["not shown in the simulated run: action car cut in",
                   "not shown in the simulated run: relation car left of ego"]
    assert generation.warnings == ["could not place: 'x'"] + new
    assert generation.note_simulated(shown) == []  # said once
    assert Generation("script", "openai").note_simulated(shown) == []  # nothing meant, nothing to compare
