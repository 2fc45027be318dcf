"""sg-blocks2: the rules SG builds pull_out, reverse and u_turn (and junction merges), the scripts pass the
bank's safety check, run in DV2S-v0 and the trace semantics find the manoeuvre.

Parses are built per the parser contract so these tests do not depend on how today's parser reads a phrase."""

import pytest

from dv2s_gym.pipeline.semantics.parsed import Entity, ParsedDescription
from scenario_bank.safety import check_script
from sg_helpers import generate_from, trace_actions


def _generate(monkeypatch, parsed: ParsedDescription, seed: int = 0):
    return generate_from(monkeypatch, parsed, seed)


def _parked_car(*actions, road="straight_road"):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    for action in actions:
        car.add_action(action)
    car.relations.append(("ahead_of", ego))
    car.relations.append(("right_of", ego))
    return ParsedDescription(text="A parked car pulls out ahead of the ego.", road=road, entities=[ego, car])


def test_pull_out_is_placed_at_the_kerb_of_a_street(monkeypatch):
    result = _generate(monkeypatch, _parked_car("pull_out"))
    # a car at the kerb does not need a second lane; it is parked on the parking lane of the parking street
    assert result.frame.map == "urban_parking"
    assert "PullOutWhenNear(egoLane.centerline" in result.script
    assert ("car", "pull_out") in result.elements.actions
    assert ("car", "right_of", "ego") in result.elements.relations
    check_script(result.script)


def test_ego_pull_out_on_a_highway_starts_on_the_hard_shoulder(monkeypatch):
    ego = Entity("ego")
    ego.add_action("pull_out")
    car = Entity("car", attrs={"noun": "car"})
    car.relations.append(("behind", ego))
    parsed = ParsedDescription(text="The ego pulls out of the shoulder.", road="highway", entities=[ego, car])
    result = _generate(monkeypatch, parsed)
    assert "t[3] is None" in result.script  # the ego's lane is the rightmost one
    # parked on the hard shoulder right of it (sg-kerb; before, the rightmost lane stood in for the shoulder)
    assert "ego = new Car right of egoSpot by Range(2.15, 2.35)" in result.script
    assert "PullOutWhenNear(egoLane.centerline" in result.script
    assert ("car", "left_of", "ego") in result.elements.relations  # traffic in the lane it pulls into


def test_u_turn_is_placed(monkeypatch):
    ego = Entity("ego")
    ego.add_action("u_turn")
    parsed = ParsedDescription(text="The ego turns round.", road=None, entities=[ego])
    result = _generate(monkeypatch, parsed)
    assert result.frame.map == "urban_two_way"
    assert "UTurnLater(" in result.script
    assert ("ego", "u_turn") in result.elements.actions
    check_script(result.script)


@pytest.mark.slow
def test_pull_out_runs_and_shows_in_the_trace(monkeypatch):
    result = _generate(monkeypatch, _parked_car("pull_out"))
    hits = sum("pull_out" in acts for acts in trace_actions(result.script, "car"))
    assert hits >= 2, hits


@pytest.mark.slow
def test_reversing_out_shows_reverse_and_pull_out(monkeypatch):
    result = _generate(monkeypatch, _parked_car("reverse", "pull_out"))
    assert {"reverse", "pull_out"} <= {a for k, a in result.elements.actions if k == "car"}
    runs = trace_actions(result.script, "car")
    assert sum("reverse" in acts for acts in runs) >= 2, runs
    assert sum("pull_out" in acts for acts in runs) >= 2, runs


@pytest.mark.slow
def test_ego_pull_out_from_the_shoulder_runs(monkeypatch):
    ego = Entity("ego")
    ego.add_action("pull_out")
    parsed = ParsedDescription(text="The ego pulls out of the shoulder.", road="highway", entities=[ego])
    result = _generate(monkeypatch, parsed)
    hits = sum("pull_out" in acts for acts in trace_actions(result.script, "ego"))
    assert hits >= 2, hits


@pytest.mark.slow
@pytest.mark.parametrize("who", ["ego", "car"])
def test_u_turn_runs_and_shows_in_the_trace(monkeypatch, who):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.relations.append(("ahead_of", ego))
    car.relations.append(("same_lane", ego))
    (ego if who == "ego" else car).add_action("u_turn")
    parsed = ParsedDescription(text="Someone turns round.", road="straight_road", entities=[ego, car])
    result = _generate(monkeypatch, parsed)
    assert (who, "u_turn") in result.elements.actions
    hits = sum("u_turn" in acts for acts in trace_actions(result.script, who, seconds=10.0))
    assert hits >= 2, hits


def _junction_merge():
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("merge")
    car.relations.append(("ahead_of", ego))
    return ParsedDescription(text="At a T-junction a car from the side road merges in ahead of the ego.",
                             road="t_junction", entities=[ego, car])


def test_a_merge_from_a_side_road_is_a_merge_not_a_cut_in(monkeypatch):
    result = _generate(monkeypatch, _junction_merge())
    assert result.frame.map == "urban_t_junction"
    assert "PullOutWhenEgoNear(" in result.script
    acts = {a for k, a in result.elements.actions if k == "car"}
    assert "merge" in acts and "cut_in" not in acts


def test_the_egos_merge_without_a_ramp_is_a_lane_change(monkeypatch):
    ego = Entity("ego")
    ego.add_action("merge")
    barrier = Entity("obstacle", attrs={"noun": "barrier"})
    barrier.relations.append(("ahead_of", ego))
    barrier.relations.append(("same_lane", ego))
    parsed = ParsedDescription(text="A barrier closes the ego's lane; the ego merges left.", road="straight_road",
                               entities=[ego, barrier])
    result = _generate(monkeypatch, parsed)
    assert result.frame.map == "urban_multilane"  # a lane to merge into in the ego's direction, in town
    assert ("ego", "lane_change_left") in result.elements.actions
    assert any("merge without an on-ramp" in w for w in result.warnings)


@pytest.mark.slow
def test_junction_merge_runs_and_shows_in_the_trace(monkeypatch):
    result = _generate(monkeypatch, _junction_merge())
    hits = sum("merge" in acts for acts in trace_actions(result.script, "car", seconds=10.0))
    assert hits >= 2, hits


def test_a_pedestrian_from_the_right_crosses_right_to_left(monkeypatch):
    ego = Entity("ego")
    ped = Entity("pedestrian", attrs={"noun": "pedestrian"})
    ped.add_action("cross")
    ped.relations.append(("right_of", ego))
    parsed = ParsedDescription(text="A pedestrian steps off the kerb on the right.", road="straight_road",
                               entities=[ego, ped])
    for seed in range(4):  # no coin toss: the side comes from the text
        script = _generate(monkeypatch, parsed, seed=seed).script
        assert "pedestrian1 = new Pedestrian right of pedestrian1Spot" in script


def test_a_swerve_back_into_lane_is_not_a_cut_in(monkeypatch):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("cut_in")
    car.add_action("swerve")
    car.relations.append(("right_of", ego))
    parsed = ParsedDescription(text="A car on the right swerves toward the ego and returns.", road="highway",
                               entities=[ego, car])
    result = _generate(monkeypatch, parsed)
    acts = {a for k, a in result.elements.actions if k == "car"}
    assert acts == {"swerve"}
    assert "SwerveAndBack(" in result.script and "CutInWhenAhead" not in result.script
    assert any("built as a swerve" in w for w in result.warnings)


def _colliding_lane_changer() -> ParsedDescription:
    """"A truck on the left changes lanes into the ego.", as the parser reads it."""
    ego = Entity("ego")
    truck = Entity("truck", attrs={"noun": "truck"})
    truck.add_action("lane_change_right")
    truck.add_action("collide")
    truck.relations.append(("left_of", ego))
    return ParsedDescription(text="A truck on the left changes lanes into the ego.", road="highway",
                             entities=[ego, truck])


def test_a_colliding_lane_changer_starts_beside_the_ego(monkeypatch):
    result = _generate(monkeypatch, _colliding_lane_changer())
    assert "param truck1_offset = Range(0, 2.5)" in result.script


@pytest.mark.slow
def test_a_colliding_lane_changer_sideswipes_the_ego(monkeypatch):
    result = _generate(monkeypatch, _colliding_lane_changer())
    runs = trace_actions(result.script, "truck")
    assert sum("collide_side" in acts for acts in runs) >= 2, runs
