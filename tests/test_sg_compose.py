"""sg-compose: the rules SG places buses and two-wheelers, copies the parser's unplaced phrases as warnings and
fails with a clear error when the main event cannot be placed.

The descriptions' parses are built here per the parser contract (``ParsedDescription``), so these tests do not
depend on how today's parser reads a phrase."""

import pytest

from dv2s_gym.pipeline.errors import GenerationError
from dv2s_gym.pipeline.semantics.parsed import Entity, ParsedDescription
from envs.errors import DV2SError
from scenario_bank.safety import check_script
from sg_helpers import generate_from, run_script, trace_actions


def _generate(monkeypatch, parsed: ParsedDescription, seed: int = 0):
    return generate_from(monkeypatch, parsed, seed)


def _run(script, seconds=6.0, seed=0):
    return run_script(script, seconds, seed)


def _lead(kind: str, action: str, road: str = "straight_road", noun: str = "") -> ParsedDescription:
    ego = Entity("ego")
    other = Entity(kind, attrs={"noun": noun or kind})
    other.add_action(action)
    other.relations.append(("ahead_of", ego))
    other.relations.append(("same_lane", ego))
    return ParsedDescription(text=f"A {noun or kind} ahead of the ego {action}s.", road=road,
                             entities=[ego, other])


@pytest.mark.parametrize("kind, cls", [("bus", "Bus"), ("motorcycle", "Motorcycle"), ("bicycle", "Bicycle")])
def test_new_kinds_get_their_model_class(monkeypatch, kind, cls):
    result = _generate(monkeypatch, _lead(kind, "brake"))
    assert f"new {cls}" in result.script
    assert check_script(result.script) == []
    assert (kind, "brake") in result.elements.actions
    assert kind in result.elements.participants


def test_a_bicycle_rides_at_bicycle_speed(monkeypatch):
    result = _generate(monkeypatch, _lead("bicycle", "keep_lane"))
    assert "param bicycle1_speed = Range(4, 6)" in result.script
    car = _generate(monkeypatch, _lead("car", "keep_lane"))
    assert "Range(4, 6)" not in car.script


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["bus", "bicycle"])
def test_new_kinds_run_and_show_in_the_trace(monkeypatch, kind):
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = _generate(monkeypatch, _lead(kind, "brake"))
    trace = _run(result.script)
    assert kind in set(trace.kinds.values())
    assert kind in elements_from_trace(trace).participants


def test_unplaced_phrases_become_warnings(monkeypatch):
    parsed = _lead("car", "brake")
    parsed.unplaced = ["while the sun sets behind the hills"]
    result = _generate(monkeypatch, parsed)
    assert "could not place: 'while the sun sets behind the hills'" in result.warnings


def test_an_unknown_kind_is_a_warning_not_a_crash(monkeypatch):
    parsed = _lead("car", "brake")
    parsed.entities.append(Entity("tram", attrs={"noun": "tram"}))
    result = _generate(monkeypatch, parsed)
    assert any("tram" in w for w in result.warnings)


def test_main_event_that_cannot_be_placed_is_a_clear_error(monkeypatch):
    parsed = _lead("car", "drift", road="intersection")
    with pytest.raises(GenerationError) as info:
        _generate(monkeypatch, parsed)
    assert isinstance(info.value, DV2SError)
    message = str(info.value)
    assert "\n" not in message and "drift" in message and "main event" in message


def test_a_placeable_main_event_does_not_raise(monkeypatch):
    result = _generate(monkeypatch, _lead("car", "brake"))
    assert result.script


def test_an_action_the_kind_cannot_do_is_a_warning_not_the_main_event(monkeypatch):
    ego = Entity("ego")
    walker = Entity("pedestrian", attrs={"noun": "pedestrian"})
    walker.add_action("go_straight")
    walker.add_action("cross")
    parsed = ParsedDescription(text="A pedestrian goes straight across the road.", road="straight_road",
                               entities=[ego, walker])
    result = _generate(monkeypatch, parsed)
    assert any("go straight" in w for w in result.warnings)
    assert ("pedestrian", "cross") in result.elements.actions


def test_undirected_lane_change_takes_a_side(monkeypatch):
    parsed = _lead("car", "lane_change", road="highway")
    result = _generate(monkeypatch, parsed)
    acts = {a for k, a in result.elements.actions if k == "car"}
    assert acts & {"lane_change_left", "lane_change_right"}
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("lane_change")
    car.relations.append(("left_of", ego))
    result = _generate(monkeypatch, ParsedDescription(text="A car left of the ego changes lanes.", road="highway",
                                                      entities=[ego, car]))
    assert ("car", "lane_change_right") in result.elements.actions


def _rear_end() -> ParsedDescription:
    """"The ego rear-ends a car.", as the parser reads it."""
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.add_action("collide")
    car.add_action("collide_rear_end")
    return ParsedDescription(text="The ego rear-ends a car.", road="straight_road", entities=[ego, car])


def test_rear_end_collision_places_the_actor_ahead_in_the_ego_lane(monkeypatch):
    parsed = _rear_end()
    result = _generate(monkeypatch, parsed)
    assert ("car", "collide") in result.elements.actions
    assert ("car", "ahead_of", "ego") in result.elements.relations
    assert not any("collide rear end" in w for w in result.warnings)


@pytest.mark.slow
def test_rear_end_collision_happens_with_that_geometry(monkeypatch):
    parsed = _rear_end()
    result = _generate(monkeypatch, parsed)
    hits = sum("collide_rear_end" in acts for acts in trace_actions(result.script, "car", seconds=10.0))
    assert hits >= 2, hits


@pytest.mark.slow
@pytest.mark.parametrize("who", ["ego", "car"])
def test_swerve_runs_and_shows_in_the_trace(monkeypatch, who):
    ego = Entity("ego")
    car = Entity("car", attrs={"noun": "car"})
    car.relations.append(("ahead_of", ego))
    car.relations.append(("same_lane", ego))
    (ego if who == "ego" else car).add_action("swerve")
    if who == "ego":
        car.add_action("keep_lane")
    parsed = ParsedDescription(text="Someone swerves.", road="straight_road", entities=[ego, car])
    result = _generate(monkeypatch, parsed)
    assert (who, "swerve") in result.elements.actions
    hits = sum("swerve" in acts for acts in trace_actions(result.script, who, seconds=8.0))
    assert hits >= 2, hits


def test_ego_bypasses_an_obstacle_in_its_lane(monkeypatch):
    ego = Entity("ego")
    ego.add_action("overtake")
    box = Entity("obstacle", attrs={"noun": "box"})
    box.relations.append(("ahead_of", ego))
    parsed = ParsedDescription(text="The ego goes around a box in its lane.", road="straight_road",
                               entities=[ego, box])
    result = _generate(monkeypatch, parsed)
    assert "OvertakeAndReturn(obstacle1" in result.script
    assert ("ego", "overtake") in result.elements.actions
