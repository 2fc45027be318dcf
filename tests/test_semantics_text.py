"""Semantic elements from description text (dv2s_gym.pipeline.semantics.text).

Labelling conventions follow the bank sidecars: a vehicle "in front of" the ego with no side is also in
its lane (same_lane); a cut-in also counts as a lane change toward the ego; a crossing pedestrian is
ahead of the ego and crosses its path; an oncoming vehicle crosses the path of an ego turning left; a
bare "road" is a straight road.
"""

from pathlib import Path

import pytest

from dv2s_gym.pipeline.semantics.lexicon import LANE_WORD
from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.semantics.text import elements_from_text, parse_description
from scenario_bank.elements import ActorKind, Elements, element_set

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenario_bank" / "scenarios"

PAPER = {
    "The ego car is on the highway and the car in front of it suddenly decelerates.": {
        "road": "highway", "participants": ["ego", "car"], "actions": [["car", "brake"]],
        "relations": [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]},
    "The ego car that is on the left lane switches to the middle lane and another car on the right lane switches "
    "also to the middle lane.": {
        "road": None, "participants": ["ego", "car"],
        "actions": [["ego", "lane_change_right"], ["car", "lane_change_left"]],
        "relations": [["car", "right_of", "ego"]]},
    "Three pedestrians crossing in the middle of the road, one going from left to right and the two others from "
    "right to left.": {
        "road": "straight_road", "participants": ["pedestrian"] * 3, "actions": [["pedestrian", "cross"]],
        "relations": []},
    "The ego vehicle was blocked by a stationary digital signboard placed on the right lane, obstructing its path. "
    "The red car ahead of the ego vehicle quickly maneuvered around the signboard to continue on its way, while the "
    "ego vehicle remained stationary. This scene takes place on a straight road where the traffic dynamics cause a "
    "temporary halt in movement.": {
        "road": "straight_road", "participants": ["ego", "car", "obstacle"],
        "actions": [["car", "overtake"], ["ego", "stop"]],
        "relations": [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]},
}

# Varied phrasings (synonyms, counts, passive voice, negation, pronouns) with what they state.
VARIED = [
    ("A white SUV suddenly cuts in from the left lane just in front of the ego vehicle on the freeway.",
     {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "cut_in"], ["car", "lane_change_right"]],
      "relations": [["car", "ahead_of", "ego"], ["car", "left_of", "ego"]]}),
    ("A lorry in the lane to the right of the ego pulls into the ego's lane.",
     {"road": None, "participants": ["ego", "truck"], "actions": [["truck", "cut_in"], ["truck", "lane_change_left"]],
      "relations": [["truck", "right_of", "ego"]]}),
    ("Two people walk across the street while the ego car slows down.",
     {"road": "straight_road", "participants": ["ego", "pedestrian", "pedestrian"],
      "actions": [["ego", "brake"], ["pedestrian", "cross"]],
      "relations": [["pedestrian", "ahead_of", "ego"], ["pedestrian", "crossing_path", "ego"]]}),
    ("The ego car narrowly avoids hitting a cyclist at the crossroads.",
     {"road": "intersection", "participants": ["ego", "bicycle"], "actions": [], "relations": []}),
    ("The ego vehicle was rear-ended by a van at the T-junction.",
     {"road": "t_junction", "participants": ["ego", "car"],
      "actions": [["car", "collide"], ["car", "collide_rear_end"], ["ego", "collide"], ["ego", "collide_rear_end"]],
      "relations": []}),
    ("The ego car turns left at the intersection while an oncoming bus goes straight.",
     {"road": "intersection", "participants": ["ego", "bus"],
      "actions": [["ego", "turn_left"], ["bus", "go_straight"]],
      "relations": [["bus", "oncoming", "ego"], ["bus", "crossing_path", "ego"]]}),
    ("An oncoming sedan drifts into the ego's lane on a country road.",
     {"road": "straight_road", "participants": ["ego", "car"], "actions": [["car", "drift"]],
      "relations": [["car", "oncoming", "ego"]]}),
    ("Debris lies in the ego's lane on the motorway and the ego car changes lanes to the left.",
     {"road": "highway", "participants": ["ego", "obstacle"], "actions": [["ego", "lane_change_left"]],
      "relations": [["obstacle", "same_lane", "ego"], ["obstacle", "ahead_of", "ego"]]}),
    ("The car behind the ego accelerates and overtakes it.",
     {"road": None, "participants": ["ego", "car"], "actions": [["car", "accelerate"], ["car", "overtake"]],
      "relations": [["car", "behind", "ego"]]}),
    ("The ego vehicle merges onto the highway from the on-ramp.",
     {"road": "merge", "participants": ["ego"], "actions": [["ego", "merge"]], "relations": []}),
    ("The ego car keeps its lane at a three-way junction while a truck turns right.",
     {"road": "three_way", "participants": ["ego", "truck"],
      "actions": [["ego", "keep_lane"], ["truck", "turn_right"]], "relations": []}),
]

NONSENSE = ["", "Lorem ipsum dolor sit amet.", "The quick brown fox jumps over the lazy dog.",
            "12345 !!! ???", "Colourless green ideas sleep furiously."]


@pytest.mark.parametrize("text", list(PAPER))
def test_paper_descriptions_give_the_expected_elements(text):
    assert elements_from_text(text) == Elements.from_dict(PAPER[text])


@pytest.mark.parametrize("text,expected", VARIED, ids=[t[:40] for t, _ in VARIED])
def test_varied_phrasings(text, expected):
    assert elements_from_text(text) == Elements.from_dict(expected)


@pytest.mark.parametrize("text", NONSENSE)
def test_nonsense_gives_nothing(text):
    assert element_set(elements_from_text(text)) == frozenset()


def test_counts_and_groups():
    parsed = parse_description("Three pedestrians crossing in the middle of the road, one going from left to right "
                               "and the two others from right to left.")
    (group,) = parsed.entities
    assert group.count == 3
    assert sorted(group.attrs["cross_dirs"]) == [("left_to_right", 1), ("right_to_left", 2)]
    assert elements_from_text("Two cars ahead of the ego brake.").participants == ("car", "car", "ego")
    assert elements_from_text("A car and another car drive ahead.").participants == ("car", "car")


def test_negation_and_nominal_forms_are_not_actions():
    assert elements_from_text("The ego car does not stop.").actions == ()
    assert elements_from_text("There is a stop sign at the junction.").actions == ()
    assert elements_from_text("The car ahead of the ego avoids a collision.").actions == ()


def _bank_entries():
    """(name, description, elements) of every shipped bank scenario, read through the bank: each has both."""
    from scenario_bank.bank import Bank

    return [(entry.name, entry.description, entry.elements) for entry in Bank(SCENARIOS)]


def bank_recall_precision():
    """Aggregate (micro) recall and precision of elements_from_text over the bank's sidecars."""
    hit = said = found = 0
    rows = []
    for name, description, elements in _bank_entries():
        truth = element_set(elements)
        got = element_set(elements_from_text(description))
        hit += len(truth & got)
        said += len(truth)
        found += len(got)
        rows.append((name, sorted(truth - got), sorted(got - truth)))
    recall = hit / said if said else 1.0
    precision = hit / found if found else 1.0
    return recall, precision, rows


def test_bank_descriptions_recall_and_precision():
    entries = _bank_entries()
    assert len(entries) >= 32 and all(description and elements for _, description, elements in entries)
    recall, precision, rows = bank_recall_precision()
    misses = [r for r in rows if r[1] or r[2]]
    assert recall >= 0.9 and precision >= 0.9, (recall, precision, misses)


@pytest.mark.parametrize("text, owner, kind", [
    ("The ego car rear-ends the car ahead of it.", "ego", "collide_rear_end"),
    ("A car ahead of the ego suddenly brakes and the ego car crashes into the back of it.", "ego", "collide_rear_end"),
    ("The ego car is rear-ended by a truck.", "truck", "collide_rear_end"),
    ("The ego car has a rear-end collision with the car in front of it.", "ego", "collide_rear_end"),
    ("An oncoming car drifts into the ego's lane and collides head-on with the ego car.", "car", "collide_head_on"),
    ("The ego car has a head-on collision with an oncoming car.", "ego", "collide_head_on"),
    ("The car runs the red light and T-bones the ego vehicle at the intersection.", "car", "collide_side"),
    ("The car sideswipes the ego car while changing lanes.", "car", "collide_side"),
])
def test_collision_types_from_text(text, owner, kind):
    """A typed collision states collide and its type for every participant (scenario_bank.elements), the same
    elements trace semantics give: here the owner and the ego or the car it hits."""
    actions = elements_from_text(text).actions
    assert (owner, "collide") in actions and (owner, kind) in actions
    typed = [a for a in actions if a[1].startswith("collide_")]
    assert {a[1] for a in typed} == {kind} and len(typed) == 2 and owner in {a[0] for a in typed}


@pytest.mark.parametrize("text", [
    "The ego car narrowly avoids a rear-end collision with the car in front of it.",
    "The ego car nearly collides with the car in front of it.",
    "A car pulls into the side of the road ahead of the ego car.",
    "The oncoming car drifts toward the ego car but does not hit it head-on.",
])
def test_no_collision_type_from_text(text):
    assert not [a for a in elements_from_text(text).actions if a[1].startswith("collide_")]


@pytest.mark.parametrize("text, lane", [
    ("A car in the left lane brakes.", Lane.LEFT), ("A car in the middle lane cuts in.", Lane.MIDDLE),
    ("A car in the right lane brakes.", Lane.RIGHT), ("A car in the adjacent lane brakes.", Lane.ADJACENT),
    ("A truck on the on-ramp merges into the highway ahead of the ego.", Lane.RAMP),
])
def test_a_participant_s_lane_is_one_of_lane(text, lane):
    """The lane the parser puts a participant in is a word of :class:`Lane`, held as a plain string."""
    entity = next(e for e in parse_description(text).entities if e.kind != ActorKind.EGO)
    assert entity.lane == lane and type(entity.lane) is str
    assert set(LANE_WORD.values()) <= set(Lane)
