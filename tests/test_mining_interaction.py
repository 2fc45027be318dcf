"""The interaction behind a mined failure (its actor and manoeuvre, read from the failure's trace), the
sentence that names it in the failure's description, and the judge's test of a simulated run against it.

The traces are built by hand (straight highway, highway-env frame: x along the road, y to the right), so
each case holds exactly the interaction it is about.
"""

from __future__ import annotations

import pytest

from dv2s_gym.mining.conversion.interaction import (failure_interaction, interaction_sentence, key_actor,
                                         shows_interaction)
from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from envs.trace import EpisodeTrace
from scenario_bank.records import Failure
from scenario_bank.elements import Elements

DT = 0.2  # the env's default policy frequency, 5 Hz
LANE = 4.0


def _drive(x0: float, y0: float, speeds, lane_shift=None):
    """States ``[x, y, heading, speed]`` of a vehicle driving along +x with the given speed per step;
    ``lane_shift = (first step, steps, dy)`` moves it sideways by ``dy`` over those steps."""
    x, y, rows = x0, y0, []
    for i, v in enumerate(speeds):
        if lane_shift and lane_shift[0] <= i < lane_shift[0] + lane_shift[1]:
            y += lane_shift[2] / lane_shift[1]
        rows.append([x, y, 0.0, v])
        x += v * DT
    return rows


def _ramp(start: float, end: float, first: int, steps: int, total: int):
    """Speeds: ``start`` until step ``first``, then linearly to ``end`` over ``steps`` steps, then ``end``."""
    out = []
    for i in range(total):
        if i < first:
            out.append(start)
        elif i < first + steps:
            out.append(start + (end - start) * (i - first + 1) / steps)
        else:
            out.append(end)
    return out


def _trace(actors, events=(), kinds=None) -> EpisodeTrace:
    n = len(actors["ego"])
    states = [{name: rows[i] for name, rows in actors.items()} for i in range(n)]
    return EpisodeTrace(scenario="hand", source="test", seed=0, scene_seed=0, params={"map": "highway_straight"},
                        config={"policy_frequency": 5}, actions=[1] * (n - 1), states=states, events=list(events),
                        kinds=kinds or {name: "car" for name in actors if name != "ego"})


def stall_behind_braking_car() -> EpisodeTrace:
    """The ego slows to a standstill on a highway while, 63 m ahead in its lane, a car brakes hard and
    stops; two cars drive on in the lanes beside it. The ego stands still 60 m behind the stopped car."""
    n = 60
    return _trace({
        "ego": _drive(0.0, 0.0, _ramp(25.0, 0.0, 0, 25, n)),
        "lead": _drive(63.0, 0.0, _ramp(25.0, 0.0, 5, 15, n)),
        "left": _drive(-10.0, -LANE, [25.0] * n),
        "right": _drive(5.0, LANE, [25.0] * n),
    })


STALL = Failure("stall", 5.0, 25)


def cut_in_with_large_gap() -> EpisodeTrace:
    """A car 63 m ahead in the lane to the ego's left, slower than the ego, changes into the ego's lane; the
    ego closes in on it until the time-to-collision is below a second."""
    n = 30
    return _trace({
        "ego": _drive(0.0, 0.0, [30.0] * n),
        "cutter": _drive(63.0, -LANE, [20.0] * n, lane_shift=(10, 5, LANE)),
        "far": _drive(-40.0, LANE, [30.0] * n),
    }, events=[{"time": 2.4, "kind": "lane_change", "actors": ["cutter"], "direction": "right"}])


CUT_IN = Failure("low_ttc", 5.6, 28, with_="cutter", with_kind="car", min_ttc=0.4)


def test_the_stall_names_the_braking_car_far_ahead():
    trace = stall_behind_braking_car()
    assert key_actor(trace, STALL) == "lead"  # in the ego's lane ahead; the cars beside it are not
    interaction = failure_interaction(trace, STALL)
    assert interaction.to_dict()["kind"] == "car" and interaction.to_dict()["side"] == "same_lane"
    assert {"brake", "stop"} <= set(interaction.to_dict()["manoeuvres"])
    assert interaction.to_dict()["gap_m"] == 63.0
    sentence = interaction_sentence(interaction)
    assert "63 m ahead" in sentence and "brakes" in sentence, sentence
    said = elements_from_text("The ego car drives in the right lane of a highway with three other cars nearby. "
                              + sentence)
    assert ("car", "brake") in said.actions and ("car", "same_lane", "ego") in said.relations


def test_the_cut_in_names_the_car_cutting_in_from_the_left():
    trace = cut_in_with_large_gap()
    interaction = failure_interaction(trace, CUT_IN)
    assert interaction.to_dict()["actor"] == "cutter" and interaction.to_dict()["side"] == "left" and interaction.to_dict()["gap_m"] == 63.0
    assert interaction.to_dict()["manoeuvres"][0] == "cut_in" and "lane_change_right" in interaction.to_dict()["manoeuvres"]
    sentence = interaction_sentence(interaction)
    assert "cuts into the ego's lane" in sentence and "left" in sentence, sentence
    assert ("car", "cut_in") in elements_from_text(sentence).actions


def test_a_description_that_names_the_interaction_is_not_told_it_again():
    interaction = failure_interaction(stall_behind_braking_car(), STALL)
    known = elements_from_text("The car in front of the ego car suddenly brakes hard.")
    assert interaction_sentence(interaction, known=known) == ""
    assert interaction_sentence(interaction, known=elements_from_text("The ego car drives on a highway.")) != ""
    assert interaction_sentence({"kind": None}) == ""


def test_a_run_without_the_braking_car_does_not_show_the_interaction():
    interaction = failure_interaction(stall_behind_braking_car(), STALL)
    n = 60
    # the ego stops on an empty highway: the same failure type, but nothing it stopped for
    alone = _trace({"ego": _drive(0.0, 0.0, _ramp(25.0, 0.0, 0, 25, n))})
    assert not shows_interaction(interaction, elements_from_trace(alone))
    # cars drive beside it and none brakes: still not the interaction
    beside = _trace({"ego": _drive(0.0, 0.0, _ramp(25.0, 0.0, 0, 25, n)),
                     "left": _drive(-10.0, -LANE, [25.0] * n), "right": _drive(5.0, LANE, [25.0] * n)})
    assert not shows_interaction(interaction, elements_from_trace(beside))
    assert shows_interaction(interaction, elements_from_trace(stall_behind_braking_car()))


def test_a_lane_change_to_either_side_shows_a_cut_in_but_braking_does_not():
    interaction = failure_interaction(cut_in_with_large_gap(), CUT_IN)
    mirrored = Elements("highway", ("ego", "car"), (("car", "lane_change_left"),))
    braking = Elements("highway", ("ego", "car"), (("car", "brake"),))
    assert shows_interaction(interaction, mirrored)
    assert not shows_interaction(interaction, braking)
    truck = Elements("highway", ("ego", "truck"), (("truck", "cut_in"),))
    assert not shows_interaction(interaction, truck)


def test_a_collision_is_shown_only_with_the_kind_colliding():
    interaction = {"failure_type": "collision", "kind": "car", "manoeuvres": ["stop"]}
    stopped = Elements(participants=("ego", "car"), actions=(("car", "stop"),))
    assert not shows_interaction(interaction, stopped)
    assert shows_interaction(interaction, Elements(participants=("ego", "car"),
                                                   actions=(("car", "stop"), ("car", "collide"))))


@pytest.mark.parametrize("failure", [Failure("collision", with_="lead", step=10),
                                     Failure("low_ttc", with_="lead", step=10)])
def test_the_partner_of_a_collision_or_low_ttc_is_the_key_actor(failure):
    assert key_actor(stall_behind_braking_car(), failure) == "lead"


def test_an_actor_without_a_manoeuvre_is_named_where_it_was_unless_the_description_places_it():
    interaction = {"failure_type": "low_ttc", "kind": "car", "manoeuvres": [], "gap_m": -2.1, "side": "right"}
    vague = elements_from_text("The ego car drives in the left lane of a highway. Three other cars drive nearby.")
    sentence = interaction_sentence(interaction, known=vague)
    assert "lane to the right" in sentence, sentence
    assert ("car", "right_of", "ego") in elements_from_text(sentence).relations
    placed = elements_from_text("A car drives in the lane to the right of the ego car.")
    assert interaction_sentence(interaction, known=placed) == ""


def _rear_end_into_steady_car(impact_drop: float, brake_before: bool = False) -> EpisodeTrace:
    """The ego speeds up into a car ahead that cruises at 24.6 m/s (or, with ``brake_before``, brakes from it to
    14 m/s over the 2 s before the impact); at the impact step the struck car's logged speed falls by
    ``impact_drop`` m/s and the ego's by as much, then both stand still."""
    n, impact = 30, 20
    lead_speeds = _ramp(24.6, 14.0, impact - 10, 10, n) if brake_before else [24.6] * n
    lead_speeds = lead_speeds[:impact] + [lead_speeds[impact - 1] - impact_drop] + [0.0] * (n - impact - 1)
    ego_speeds = _ramp(25.0, 35.0, 0, impact, n)[:impact] + [35.0 - impact_drop] + [0.0] * (n - impact - 1)
    lead_x = 35.0 + sum(v * DT for v in ego_speeds[:impact]) - sum(v * DT for v in lead_speeds[:impact]) - 30.5
    return _trace({"ego": _drive(0.0, 0.0, ego_speeds), "lead": _drive(lead_x, 0.0, lead_speeds)},
                  events=[{"kind": "collision", "time": impact * DT, "actors": ["ego", "lead"]}])


def test_the_speed_an_impact_takes_away_is_no_braking_of_the_struck_car():
    from dv2s_gym.mining.behaviour import extract_behaviour
    from dv2s_gym.mining.conversion.interaction import trace_shows_interaction
    from dv2s_gym.mining.monitors import Failure

    steady = _rear_end_into_steady_car(impact_drop=3.1)
    failure = Failure("collision", 4.0, 20, with_="lead")
    assert ("car", "brake") not in elements_from_trace(steady).actions
    assert "brake" not in failure_interaction(steady, failure).manoeuvres
    behaviour = extract_behaviour(steady, Failure(type="collision", time=4.0, step=20, with_="lead", with_kind="car"))
    assert (behaviour.actor_manoeuvre, behaviour.ego_manoeuvre) == ("steady", "keeping_lane")
    braking = {"failure_type": "collision", "actor": "lead", "kind": "car", "manoeuvres": ["brake"]}
    assert not trace_shows_interaction(braking, steady)
    real = _rear_end_into_steady_car(impact_drop=3.1, brake_before=True)
    assert "brake" in failure_interaction(real, failure).manoeuvres
    assert trace_shows_interaction(braking, real)


def test_the_judge_wants_the_manoeuvre_and_the_collision_from_the_same_actor():
    from dv2s_gym.mining.conversion.interaction import trace_shows_interaction

    n = 30
    # a car beside the ego brakes hard; another car ahead, cruising, is the one the ego hits
    trace = _trace({"ego": _drive(0.0, 0.0, [30.0] * n),
                    "beside": _drive(0.0, LANE, _ramp(30.0, 10.0, 5, 10, n)),
                    "ahead": _drive(60.0, 0.0, [20.0] * n)},
                   events=[{"kind": "collision", "time": 5.8, "actors": ["ego", "ahead"]}])
    braking = {"failure_type": "collision", "actor": "lead", "kind": "car", "manoeuvres": ["brake"]}
    assert shows_interaction(braking, elements_from_trace(trace))  # the elements mix the two cars
    assert not trace_shows_interaction(braking, trace)


def test_a_car_beside_the_ego_does_not_show_a_stall_behind_a_car_in_its_lane():
    from dv2s_gym.mining.conversion.interaction import trace_shows_interaction

    n = 40
    behind = _trace({"ego": _drive(0.0, 0.0, _ramp(25.0, 0.0, 0, 20, n)), "slow": _drive(40.0, 0.0, [0.0] * n)})
    interaction = failure_interaction(behind, Failure("stall", step=n - 1))
    assert (interaction.kind, interaction.side) == ("car", "same_lane")
    assert trace_shows_interaction(interaction, behind)
    beside = _trace({"ego": _drive(0.0, 0.0, _ramp(25.0, 0.0, 0, 20, n)), "other": _drive(40.0, LANE, [0.0] * n)})
    assert shows_interaction(interaction, elements_from_trace(beside))  # kind alone: any car anywhere
    assert not trace_shows_interaction(interaction, beside)
