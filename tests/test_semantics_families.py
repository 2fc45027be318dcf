"""The description parser on phrasings it was not first written for (issue 10), one test per phrase family.

Sentences are written for these tests (not taken from the held-out evaluation set).
"""

import pytest

from dv2s_gym.pipeline.semantics.text import elements_from_text, parse_description


def _kinds(text):
    return sorted(elements_from_text(text).participants)


def _actions(text):
    return {tuple(a) for a in elements_from_text(text).actions}


# ----------------------------------------------------------------------------- actors

@pytest.mark.parametrize("text, kinds", [
    ("A motorcyclist filters past the ego car.", ["ego", "motorcycle"]),
    ("A cyclist rides along the kerb next to the ego vehicle.", ["bicycle", "ego"]),
    ("A teenager on an e-scooter waits at the corner.", ["bicycle"]),
    ("A city bus pulls away from the bus stop ahead of the ego car.", ["bus", "ego"]),
    ("A white van and a Toyota Prius are parked on the left.", ["car", "car"]),
    ("The adversarial agent accelerates towards the ego.", ["car", "ego"]),
    ("A Ford F-150 and a Harley-Davidson wait at the lights.", ["car", "motorcycle"]),
])
def test_actor_kinds(text, kinds):
    assert _kinds(text) == kinds


@pytest.mark.parametrize("text, noun", [
    ("The AV brakes hard.", "av"),
    ("The test vehicle brakes hard.", "test vehicle"),
    ("The subject vehicle brakes hard.", "subject vehicle"),
    ("V1 brakes hard.", "v1"),
    ("We brake hard.", "we"),
])
def test_ego_aliases(text, noun):
    parsed = parse_description(text)
    assert parsed.entities[0].kind == "ego" and parsed.entities[0].attrs["noun"] == noun
    assert ("ego", "brake") in _actions(text)


def test_numbered_vehicles_are_distinct_and_us_is_the_ego():
    parsed = parse_description("V2 rear-ends V3 while a truck cuts in front of us.")
    assert sorted(e.kind for e in parsed.entities) == ["car", "car", "ego", "truck"]
    v2 = next(e for e in parsed.entities if e.attrs.get("noun") == "v2")
    assert v2.has("collide_rear_end") and v2.detail("collide")["with"].attrs["noun"] == "v3"


# ----------------------------------------------------------------------------- actions

@pytest.mark.parametrize("text, expected", [
    ("The ego vehicle bypasses a stalled truck.", ("ego", "overtake")),
    ("The AV overtakes a slow tractor-trailer on the left.", ("ego", "overtake")),
    ("A black sedan cuts off the ego car.", ("car", "cut_in")),
    ("The ego vehicle is cut off by a delivery van.", ("car", "cut_in")),
    ("An SUV makes a U-turn in front of the ego.", ("car", "u_turn")),
    ("A pickup reverses out of a driveway.", ("car", "reverse")),
    ("A pickup reverses out of a driveway.", ("car", "pull_out")),
    ("The truck backs up towards the ego car.", ("truck", "reverse")),
    ("The ego vehicle swerves to avoid debris.", ("ego", "swerve")),
    ("A motorcyclist weaves through traffic.", ("motorcycle", "lane_change")),
    ("A parked car pulls out of its parking spot.", ("car", "pull_out")),
    ("A bus changes lanes ahead of the ego.", ("bus", "lane_change")),
])
def test_actions(text, expected):
    assert expected in _actions(text)


def test_weaving_and_undirected_lane_changes_carry_their_details():
    moto = parse_description("A motorcyclist weaves through traffic.").entities[0]
    assert moto.detail("lane_change")["weave"] is True
    car = parse_description("A car changes lanes to the left.").entities[0]
    assert car.has("lane_change_left") and not car.has("lane_change")


def test_pedestrian_dashing_out_from_behind_something():
    parsed = parse_description("A child dashes out from behind a parked van in front of the ego car.")
    child = next(e for e in parsed.entities if e.kind == "pedestrian")
    cross = child.detail("cross")
    assert child.has("cross") and cross["sudden"] is True and cross["from_behind"].kind == "car"
    elements = elements_from_text("A child dashes out from behind a parked van in front of the ego car.")
    assert ("pedestrian", "behind", "car") not in elements.relations  # occlusion, not a position
    assert ("pedestrian", "cross") in _actions("A jogger appears from behind a bus and crosses.")


def test_unprotected_left_turn():
    parsed = parse_description("The AV makes an unprotected left turn while an oncoming car goes straight.")
    ego = parsed.ego
    assert ego.has("turn_left") and ego.detail("turn_left")["unprotected"] is True
    assert ("car", "crossing_path", "ego") in {tuple(r) for r in parsed.elements().relations}
    assert ("ego", "turn_left") in _actions("The ego vehicle is on an unprotected left at the junction.")


def test_fronted_clauses_take_the_main_subject():
    assert {("ego", "turn_right"), ("ego", "brake")} <= _actions("After turning right, the ego car brakes.")
    assert ("truck", "lane_change") in _actions("Having changed lanes, the truck slows to a crawl.")


def test_turn_lane_is_not_a_turn():
    assert _actions("The ego car drives in the left-turn lane.") == set()
    assert ("ego", "stop") in _actions("The ego car waits in the left-turn lane.")


# ----------------------------------------------------------------------------- negation, quantity

def test_no_other_vehicles_is_an_absence_not_a_vehicle():
    parsed = parse_description("The ego drives on an empty street with no other vehicles and no pedestrians.")
    assert [e.kind for e in parsed.entities] == ["ego"]
    assert set(parsed.absent) == {"car", "truck", "bus", "motorcycle", "pedestrian"}


def test_without_an_intersection():
    parsed = parse_description("A straight road without an intersection; a car ahead of the ego brakes.")
    assert parsed.road == "straight_road" and parsed.features["no_junction"] is True


@pytest.mark.parametrize("text, kinds", [
    ("Two vehicles approach the junction: a bus and a motorcycle.", ["bus", "motorcycle"]),
    ("Three vehicles are involved: the ego, a lead car and a truck.", ["car", "ego", "truck"]),
    ("Two cars ahead of the ego brake.", ["car", "car", "ego"]),
])
def test_counts_add_up(text, kinds):
    assert _kinds(text) == kinds


# ----------------------------------------------------------------------------- roads

@pytest.mark.parametrize("text, road, features", [
    ("The ego enters a roundabout.", "roundabout", {}),
    ("The ego drives on a multi-lane urban road.", "straight_road", {"multi_lane": True}),
    ("The ego drives on a four-lane city street.", "straight_road", {"lanes": 2, "multi_lane": True}),
    ("A van waits at a Y-junction.", "three_way", {"junction_shape": "y"}),
    ("A van waits at a three-way intersection.", "three_way", {}),
    ("A car sits in the right turn lane of the intersection.", "intersection", {"turn_lane": "right"}),
    ("Cars are parked in the parking lane of the street.", "straight_road", {"parking_lane": True}),
    ("A truck is stopped on the hard shoulder of the motorway.", "highway", {"shoulder": True}),
    ("The ego car takes the off-ramp of the freeway.", "highway", {"ramp": "off"}),
])
def test_roads_and_features(text, road, features):
    parsed = parse_description(text)
    assert parsed.road == road
    for key, value in features.items():
        assert parsed.features.get(key) == value, parsed.features


def test_merge_is_not_always_an_on_ramp():
    assert parse_description("On the highway the two lanes merge into one.").road == "highway"
    assert parse_description("The ego merges from the on-ramp.").road == "merge"


# ----------------------------------------------------------------------------- collision geometry

@pytest.mark.parametrize("text, who, kind", [
    ("A bus rear-ends the ego vehicle.", "bus", "collide_rear_end"),
    ("A motorcyclist strikes the side of the ego car.", "motorcycle", "collide_side"),
    ("An oncoming van hits the AV head-on.", "car", "collide_head_on"),
])
def test_collision_geometry(text, who, kind):
    assert {(who, "collide"), (who, kind)} <= _actions(text)


def test_collision_between_two_actors_gives_both_with_each_other():
    parsed = parse_description("A side-impact crash happens between the ego and a bus.")
    bus = next(e for e in parsed.entities if e.kind == "bus")
    assert parsed.ego.has("collide_side") and bus.has("collide_side")
    assert parsed.ego.detail("collide")["with"] is bus and bus.detail("collide")["with"] is parsed.ego


# ----------------------------------------------------------------------------- triggers

def test_must_stop_for_a_conflict_is_reactive():
    parsed = parse_description("At the junction the AV must stop for the crossing cyclist.")
    cyclist = next(e for e in parsed.entities if e.kind == "bicycle")
    assert parsed.ego.detail("stop")["trigger"] == {"kind": "conflict", "with": cyclist}
    assert cyclist.has("cross")


def test_must_stop_without_object_finds_the_conflicting_actor():
    parsed = parse_description("At the four-way intersection the ego must stop while a car goes straight across.")
    car = next(e for e in parsed.entities if e.kind == "car")
    assert parsed.ego.detail("stop")["trigger"] == {"kind": "conflict", "with": car}


def test_yield_and_numbers():
    parsed = parse_description("The ego yields to a bus. A truck brakes 25 m ahead of the ego at 60 mph.")
    bus = next(e for e in parsed.entities if e.kind == "bus")
    assert parsed.ego.detail("stop")["trigger"]["with"] is bus
    truck = next(e for e in parsed.entities if e.kind == "truck")
    assert truck.detail("brake")["trigger"] == {"kind": "distance", "meters": 25.0}
    assert truck.attrs["speed_kph"] == pytest.approx(96.6)


# ----------------------------------------------------------------------------- unplaced phrases

def test_unplaced_phrases_are_reported_verbatim():
    parsed = parse_description("The ego car brakes, and then the car levitates gracefully over the Road.")
    assert parsed.unplaced == ["the car levitates gracefully over the Road"]
    assert parse_description("The ego car brakes on the highway.").unplaced == []


def test_every_clause_is_placed_or_reported():
    text = "A truck is on the left. The ego hums a tune. A bus turns right."
    parsed = parse_description(text)
    assert parsed.unplaced == ["The ego hums a tune"]


# ----------------------------------------------------------------------------- clause structure

def test_relative_pronoun_refers_to_the_last_actor_and_coordinated_subjects_share_the_verb():
    assert ("pedestrian", "cross") in _actions(
        "The ego vehicle, travelling at 50 km/h, encounters a jaywalker who runs across the street.")
    assert {("pedestrian", "cross"), ("bicycle", "cross")} <= _actions(
        "Two pedestrians and a cyclist cross the street in front of the AV.")


def test_reduced_relatives_belong_to_their_noun():
    acts = _actions("A car turning right collides with a pedestrian crossing the road.")
    assert ("pedestrian", "cross") in acts and ("car", "cross") not in acts and ("car", "turn_right") in acts


def test_crash_report_style():
    text = ("V1 was stopped at a three-way intersection. V1 proceeded and was struck on the right side by V2, "
            "which was traveling west.")
    acts = _actions(text)
    assert {("car", "collide"), ("car", "collide_side"), ("ego", "stop")} <= acts
    assert parse_description(text).unplaced == []


def test_pull_over_and_signals():
    assert {("ego", "lane_change_right"), ("ego", "stop")} <= _actions("The ego pulls over onto the shoulder.")
    assert parse_description("There is no traffic light at the junction.").features["signals"] is False
    assert parse_description("The car waits at a red light.").features["signals"] is True


def test_engineer_notes_style():
    parsed = parse_description("Ego: straight; NPC1: cut-in from left at 20m, then hard brake.")
    npc = next(e for e in parsed.entities if e.kind == "car")
    assert npc.attrs["noun"] == "npc1" and npc.has("cut_in") and npc.has("brake")
    assert not parsed.ego.actions
    parsed = parse_description("Adversarial pedestrian crosses from the right when the ego is 15 m away.")
    ped = next(e for e in parsed.entities if e.kind == "pedestrian")
    assert ped.detail("cross")["trigger"] == {"kind": "distance", "meters": 15.0} and parsed.unplaced == []


def test_rider_on_a_bike_is_one_bicycle_and_rows_of_parked_cars_stay():
    text = ("The ego car drives down a residential street with cars parked on both sides while a kid on a bike "
            "rides out of a driveway.")
    parsed = parse_description(text)
    assert sorted(parsed.elements().participants) == ["bicycle", "car", "car", "ego"]
    assert ("bicycle", "pull_out") in _actions(text) and parsed.features["parking_lane"] is True


def test_no_stop_from_a_four_way_stop_and_lost_control():
    acts = _actions("The ego must stop at the stop line because a car approaches from the left at the 4-way stop.")
    assert ("ego", "stop") in acts and ("car", "stop") not in acts
    assert ("car", "drift") in _actions("A sedan loses control in front of the AV.")  # unintended: drift
    assert ("ego", "brake") not in _actions("The ego overtakes a slow tractor.")


def test_crash_typology_phrases():
    assert ("car", "crossing_path", "ego") in {tuple(r) for r in elements_from_text(
        "The ego vehicle is struck by a crossing vehicle.").relations}
    assert ("ego", "drift") in _actions("The ego vehicle departs the road edge on a curve.")
    assert ("car", "pull_out") in _actions("A vehicle parked on the shoulder pulls into traffic in front of the ego.")
    assert ("car", "lane_change_right") in _actions("A van pulls alongside the ego and then merges right.")
    rels = {tuple(r) for r in elements_from_text("The ego is following a bus.").relations}
    assert ("bus", "ahead_of", "ego") in rels and ("bus", "behind", "ego") not in rels
    assert parse_description("A truck crosses at a non-signalized junction.").features["signals"] is False


@pytest.mark.parametrize("text, kind", [
    ("The ego car collides with the car in front of it.", "collide_rear_end"),
    ("The ego car hits a pedestrian.", "collide_side"),
    ("An oncoming truck collides with the ego.", "collide_head_on"),
    ("The front of V2 impacted the right side of V1.", "collide_side"),
])
def test_untyped_collisions_get_a_type_for_every_participant(text, kind):
    typed = [tuple(a) for a in elements_from_text(text).actions if a[1].startswith("collide")]
    kinds = {a[1] for a in typed}
    assert kinds == {"collide", kind} and len(typed) == 4


def test_animals_and_test_names():
    assert _kinds("A deer crosses the rural road in front of the AV.") == ["ego", "obstacle"]
    assert ("obstacle", "cross") in _actions("A deer crosses the rural road in front of the AV.")
    assert _kinds("Car-to-Car Rear stationary: the vehicle under test drives towards a stationary target car.") \
        == ["car", "ego"]
    assert _kinds("urban 2-lane rd, ped dashes out from behind parked bus (L side) ahead of ego") == \
        ["bus", "ego", "pedestrian"]


def test_occluders_and_kerb_sides():
    rels = {tuple(r) for r in elements_from_text(
        "A boy runs out from behind a parked lorry on the right into the path of the AV.").relations}
    assert {("truck", "ahead_of", "ego"), ("pedestrian", "crossing_path", "ego")} <= rels
    rels = {tuple(r) for r in elements_from_text(
        "A woman hidden behind a stopped bus steps out in front of the ego car.").relations}
    assert ("bus", "ahead_of", "ego") in rels and ("pedestrian", "behind", "bus") not in rels
    rels = {tuple(r) for r in elements_from_text("A jogger crosses from the left kerb in front of the ego.").relations}
    assert ("pedestrian", "left_of", "ego") in rels


def test_following_merging_and_rural_highways():
    rels = {tuple(r) for r in elements_from_text("The test vehicle follows a white hatchback.").relations}
    assert ("car", "ahead_of", "ego") in rels
    assert {("car", "merge"), ("car", "lane_change_left")} <= _actions("A taxi merges left in front of us.")
    assert parse_description("A tractor drives on a two-lane rural highway.").road == "straight_road"
    assert parse_description("A truck drives on the interstate.").road == "highway"
    assert {("car", "collide_head_on"), ("ego", "collide_head_on")} <= _actions(
        "V1 and V2 drove in opposite directions and collided front to front.")


def test_appositions_name_the_vehicle_before_them():
    assert _kinds("V1, a grey Honda Accord, was northbound when V2, a moped, struck its side.") == \
        ["ego", "motorcycle"]
    assert {("motorcycle", "collide_side"), ("ego", "collide_side")} <= _actions(
        "V1, a grey Honda Accord, was northbound when V2, a moped, struck its side.")


def test_contact_backing_and_cross_traffic():
    assert {("car", "collide"), ("ego", "collide")} <= _actions(
        "A hatchback in the adjacent lane to its left drifted over and made contact with the AV.")
    assert ("ego", "collide_side") in _actions("The subject vehicle backs into the side of a parked SUV.")
    rels = {tuple(r) for r in elements_from_text(
        "At a four-way junction a bus from V1's right goes straight while V1 goes straight.").relations}
    assert {("bus", "right_of", "ego"), ("bus", "crossing_path", "ego")} <= rels
    rels = {tuple(r) for r in elements_from_text(
        "At the intersection a car from the right turns right into the ego's lane ahead of it.").relations}
    assert ("car", "crossing_path", "ego") not in rels
    assert ("ego", "turn_left") in _actions("4-way ixn, ego turns L after a bus passes.")


def test_brakes_to_a_stop_bus_stops_and_parts():
    assert {("ego", "brake"), ("ego", "stop")} <= _actions("The ego brakes to a stop behind a cow.")
    assert ("bus", "stop") in _actions("A bus stops at the bus stop ahead of the ego.")
    assert _kinds("The ego vehicle's tyre bursts on the motorway.") == ["ego"]
    assert _kinds("A cyclist rides ahead of the test vehicle and the vehicle approaches from behind.") == \
        ["bicycle", "ego"]


def test_another_without_a_noun_and_both():
    text = ("The ego is in the middle lane of a three-lane motorway; a van in the left lane ahead and another in the "
            "right lane ahead both cut into the middle lane in front of the ego.")
    elements = elements_from_text(text)
    assert elements.participants == ("car", "car", "ego")
    assert {("car", "cut_in"), ("car", "lane_change_left"), ("car", "lane_change_right")} <= _actions(text)
    assert {("car", "left_of", "ego"), ("car", "right_of", "ego")} <= {tuple(r) for r in elements.relations}


def test_place_phrase_before_the_subject_and_blocking():
    assert ("ego", "lane_change_left") in _actions("On the highway the ego car changes lanes to the left.")
    rels = {tuple(r) for r in elements_from_text("A barrier blocks the ego's lane ahead.").relations}
    assert {("obstacle", "same_lane", "ego"), ("obstacle", "ahead_of", "ego")} <= rels
    assert _kinds("An adversarial agent vehicle cuts off the AV.") == ["car", "ego"]


def test_alias_possessives_and_part_subjects():
    rels = {tuple(r) for r in elements_from_text(
        "A pedestrian walks in the test vehicle's lane ahead of it.").relations}
    assert ("pedestrian", "same_lane", "ego") in rels
    assert {("car", "collide"), ("ego", "collide")} <= _actions(
        "V2 merged left, and the right front of V1 struck the left rear of V2.")


def test_rewritten_words_never_show_up_as_unplaced():
    for text in ("Car-to-Pedestrian Nearside Adult: an adult crosses in front of the vehicle under test.",
                 "The ego brakes. No other vehicles are involved.",
                 "A man hidden behind a parked van steps out in front of the AV."):
        assert parse_description(text).unplaced == [], text
