"""The rule-based Scenario Generator (dv2s_gym.pipeline.sg.rules): safe, compilable, runnable scripts."""

import json
from pathlib import Path

import pytest

from dv2s_gym.pipeline.sg.rules import SGResult, generate_rules
from scenario_bank.elements import Elements, element_set
from scenario_bank.safety import check_script

pytestmark = pytest.mark.usefixtures("in_process_simulator")

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenario_bank" / "scenarios"

PAPER = [
    "The ego car is on the highway and the car in front of it suddenly decelerates.",
    "The ego car that is on the left lane switches to the middle lane and another car on the right lane switches "
    "also to the middle lane.",
    "Three pedestrians crossing in the middle of the road, one going from left to right and the two others from "
    "right to left.",
]
USE_CASES = ["highway_lead_vehicle_brakes", "highway_onramp_insertion", "urban_pedestrian_crossing",
             "urban_left_turn_oncoming", "urban_pull_back_in"]
USE_CASE_FALLBACK = {
    "highway_lead_vehicle_brakes": "The ego car drives on a multi-lane highway and the car in front of it suddenly "
                                   "brakes hard.",
    "highway_onramp_insertion": "The ego car drives in the right lane of a highway while a car from the on-ramp "
                                "accelerates and merges into the lane in front of it.",
    "urban_pedestrian_crossing": "The ego car drives on a two-way urban street and a pedestrian steps off the "
                                 "sidewalk and crosses the road in front of it.",
    "urban_left_turn_oncoming": "The ego car turns left at a four-way urban intersection while oncoming cars go "
                                "straight through it.",
    "urban_pull_back_in": "A faster car overtakes the ego car on an urban highway and pulls back into the ego's "
                          "lane just ahead of it.",
}
VARIED = [
    "The ego vehicle was blocked by a stationary digital signboard placed on the right lane, obstructing its path. "
    "The red car ahead of the ego vehicle quickly maneuvered around the signboard to continue on its way, while the "
    "ego vehicle remained stationary. This scene takes place on a straight road.",
    "A truck in the lane to the right of the ego slowly pulls into the ego's lane in front of it on the motorway.",
    "A car suddenly cuts in from the left lane just in front of the ego vehicle on the freeway.",
    "The ego vehicle approaches a stopped car in its lane on a city street while an oncoming car passes.",
    "An oncoming car drifts into the ego's lane on a two-way road and then steers back.",
    "A child suddenly runs across the street in front of the ego car.",
    "The ego car turns right at the intersection while a pedestrian crosses the road it turns into.",
    "The ego vehicle goes straight through the crossroads and a car from the right side crosses its path.",
    "At a T-junction the ego car turns left while an oncoming car goes straight.",
    "The ego car changes lanes to the left on the highway to overtake a slow truck ahead of it.",
    "A car behind the ego accelerates and rear-ends it on the highway.",
    "There are traffic cones blocking the ego's lane on the highway and the ego car stops behind them.",
    "The lead vehicle slows down and stops, and the ego vehicle brakes behind it on a straight road.",
    "The car on the left of the ego speeds up and changes lanes to the right in front of it.",
    "It is raining at night on the freeway; two trucks ahead of the ego brake hard.",
    "The ego car drives in the right lane of a highway with an on-ramp. No other road user comes near the ego car.",
]
UNPLACEABLE = {
    "A helicopter lands on the road in front of the ego car.": "helicopter",
    "The ego car drives around a roundabout with a tram crossing.": "tram",
    "An oncoming truck passes the ego car on the highway.": "oncoming",
}


def _bank_description(name):
    for path in (SCENARIOS / f"{name}.json", SCENARIOS / name / "meta.json"):
        if path.exists():
            return json.loads(path.read_text())["description"]
    return USE_CASE_FALLBACK[name]


ALL = PAPER + [_bank_description(n) for n in USE_CASES] + VARIED


def _run(script, seconds=5.0, seed=0):
    from envs.dv2s_env import DV2SEnv

    env = DV2SEnv(scenario=script, config={"duration": seconds, "ego_policy": "scenic"})
    try:
        env.reset(seed=seed)
        done = False
        steps = 0
        while not done:
            _, _, terminated, truncated, info = env.step(1)
            done = terminated or truncated
            steps += 1
        return env.unwrapped.trace, steps
    finally:
        env.close()


@pytest.mark.parametrize("description", ALL, ids=[d[:45] for d in ALL])
def test_generated_script_is_safe_compiles_samples_and_runs(description):
    from envs.scenarios import compile_scenario

    result = generate_rules(description, seed=0)
    assert isinstance(result, SGResult) and result.backend == "rules" and result.context_hash
    assert check_script(result.script) == []
    for section in ("# 1. Map and global parameters", "# 2. Adversarial behaviours", "# 3. Road geometry",
                    "# 4. Spawn positions"):
        assert section in result.script
    assert isinstance(result.elements, Elements)
    compiled = compile_scenario(result.script, name="sg_rules_test")
    for seed in range(6):
        compiled.sample(seed)  # every seed samples a scene (sampling speed is in bench/)
    trace, steps = _run(result.script, seconds=5.0)
    assert steps >= 1 and "ego" in trace.states[0]


@pytest.mark.slow
@pytest.mark.parametrize("description,word", list(UNPLACEABLE.items()), ids=list(UNPLACEABLE.values()))
def test_unplaceable_content_is_reported(description, word):
    from envs.scenarios import compile_scenario

    result = generate_rules(description, seed=0)
    assert any(word in w for w in result.warnings), result.warnings
    assert check_script(result.script) == []
    compile_scenario(result.script, name="sg_rules_warning").sample(0)


def test_unplaceable_main_event_is_a_clear_error():
    """The ego's own manoeuvre is the main event when nobody else acts: a turn on a highway cannot be placed."""
    from dv2s_gym.pipeline.errors import GenerationError

    with pytest.raises(GenerationError, match="main event 'ego turn left'"):
        generate_rules("The ego car turns left on the highway.", seed=0)


def test_an_action_the_map_cannot_show_is_warned_and_the_main_event_still_decides():
    """The ego can cross (elements.CAN_DO), but no map of the rules SG builds it: on a street it is warned about
    and dropped; when it is the main event, the description is refused."""
    from dv2s_gym.pipeline.errors import GenerationError

    result = generate_rules("The ego crosses the street while a car brakes ahead.", seed=0)
    assert "'ego cross' cannot be realised on map urban_two_way: not placed" in result.warnings
    assert ("action", "car", "brake") in element_set(result.elements)
    assert ("action", "ego", "cross") not in element_set(result.elements)
    with pytest.raises(GenerationError, match="main event 'ego cross'"):
        generate_rules("The ego car crosses the road.", seed=0)


def test_every_lane_role_has_its_spawn_function():
    from dv2s_gym.pipeline.sg.rules.lane_spawn import SPAWNERS
    from dv2s_gym.pipeline.sg.rules.roles import Role

    assert set(SPAWNERS) == set(Role)
    assert Role.FAR_SIDE == "far_side" and f"{Role.FAR_SIDE}" == "far_side"  # warnings name roles by their string


def test_the_capability_table_covers_every_participant_with_known_actions():
    from scenario_bank.elements import ACTIONS, CAN_DO, PARTICIPANTS

    assert set(CAN_DO) == set(PARTICIPANTS)
    assert all(actions <= set(ACTIONS) for actions in CAN_DO.values())
    assert CAN_DO["pedestrian"] == {"cross", "stop", "collide", "collide_rear_end", "collide_side", "collide_head_on"}
    assert not CAN_DO["obstacle"]


def test_deterministic_given_the_seed():
    for description in PAPER + VARIED[:4]:
        assert generate_rules(description, seed=3).script == generate_rules(description, seed=3).script
    assert generate_rules(PAPER[0]).script == generate_rules(PAPER[0], seed=0).script


def test_frame_and_intended_elements_follow_the_description():
    result = generate_rules(PAPER[1], seed=0)
    assert result.frame.map == "highway_straight"
    assert result.frame.ego.lane == "left" and result.frame.ego.actions == ["lane_change_right"]
    (car,) = result.frame.actors
    assert car.kind == "car" and "lane_change_left" in car.actions and "right_of" in car.relations
    shown = element_set(result.elements)
    assert {("action", "ego", "lane_change_right"), ("action", "car", "lane_change_left"),
            ("relation", "car", "right_of", "ego")} <= shown
    three = generate_rules(PAPER[2], seed=0)
    assert three.frame.map == "urban_two_way"
    assert three.script.count("new Pedestrian") == 3
    assert three.script.count("heading - 90 deg") == 1 and three.script.count("heading + 90 deg") == 2


def test_empty_description_is_refused():
    with pytest.raises(ValueError, match="empty"):
        generate_rules("   ")


@pytest.mark.slow
@pytest.mark.parametrize("description", PAPER + [_bank_description(n) for n in USE_CASES],
                         ids=[d[:45] for d in PAPER + USE_CASES])
def test_described_elements_happen_in_simulation(description):
    """Semantic preservation: most elements of the description show up in a 10 s episode."""
    from dv2s_gym.pipeline.semantics.text import elements_from_text
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = generate_rules(description, seed=0)
    described = element_set(elements_from_text(description))
    scores = []
    for seed in range(3):
        trace, _ = _run(result.script, seconds=10.0, seed=seed)
        simulated = element_set(elements_from_trace(trace))
        scores.append(len(described & simulated) / len(described))
    assert sum(scores) / len(scores) >= 0.8, scores


@pytest.mark.slow
@pytest.mark.parametrize("description, map_name", [
    ("A pedestrian stands on the side of the road.", "urban_two_way"),
    ("A pedestrian stands on the side of the highway.", "highway_straight"),
])
def test_standing_pedestrian_on_a_map_without_a_junction(description, map_name):
    """Before: UnboundLocalError in _spawn_lane_pedestrians for any pedestrian who does not cross."""
    import math

    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    result = generate_rules(description, seed=0)
    assert result.frame.map == map_name
    assert check_script(result.script) == []
    assert "StandStill()" in result.script and "CrossWhenEgoNear" not in result.script
    for seed in range(3):
        trace, steps = _run(result.script, seconds=4.0, seed=seed)
        names = [n for n in trace.states[0] if trace.kinds.get(n) == "pedestrian"]
        assert len(names) == 1 and steps >= 19
        ego0 = trace.states[0]["ego"]
        first = trace.states[0][names[0]]
        for states in trace.states:
            x, y = states[names[0]][:2]
            assert math.hypot(x - first[0], y - first[1]) < 0.2  # stands still
            # beside the ego's lane, never in it (ego frame: lateral offset of the pedestrian)
            lateral = (x - ego0[0]) * math.sin(ego0[2]) - (y - ego0[1]) * math.cos(ego0[2])
            assert abs(lateral) > 1.75
        elements = elements_from_trace(trace)
        assert "pedestrian" in elements.participants
        assert ("pedestrian", "cross") not in elements.actions
        assert ("pedestrian", "crossing_path", "ego") not in elements.relations
