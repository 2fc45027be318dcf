"""The actor-bound story checker (dv2s_gym/story_check.py) on hand-built traces (no simulation).

Frame: highway-env's (y drawn downward), so the lane to the ego's left is at y = -3.5.
Every rule has a trace that satisfies it and one that breaks it.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from dv2s_gym.story_check import StoryError, check_story, normalize_story, resolve_actors

DT = 0.2
N = 51  # 10 s


def ego_track(speed=20.0, n=N):
    return [[speed * i * DT, 0.0, 0.0, speed] for i in range(n)]


def trace(actors, events=(), kinds=None):
    """A trace of ``actors`` (name -> rows [x, y, heading, speed] per step, None where absent)."""
    states = []
    for i in range(N):
        state = {}
        for name, rows in actors.items():
            if i < len(rows) and rows[i] is not None:
                state[name] = list(rows[i])
        states.append(state)
    kinds = dict(kinds or {})
    kinds.setdefault("ego", "ego")
    for name in actors:
        kinds.setdefault(name, "car")
    return SimpleNamespace(states=states, events=list(events), config={"policy_frequency": 5}, params={},
                           kinds=kinds)


def car(x0, y_of, speed):
    """A car starting at x0 at ``speed``, its y at step i from ``y_of(i)``."""
    return [[x0 + speed * i * DT, y_of(i), 0.0, speed] for i in range(N)]


def cut_in_car(start_x=-10.0, speed=26.0, change_at=25, ego_speed=20.0):
    """A car in the left lane, faster than the ego, sliding into the ego's lane over 10 steps from ``change_at``."""
    def y(i):
        u = min(max((i - change_at) / 10.0, 0.0), 1.0)
        return -3.5 * (1.0 - u)
    return car(start_x, y, speed)


CUT_IN = {
    "actors": {"cutter": "car"},
    "steps": [
        {"actor": "cutter", "action": "overtake", "relations": [["left_of", "ego"]]},
        {"actor": "cutter", "action": "cut_in", "relations": [["ahead_of", "ego"]], "within_s": 3.0},
    ],
}


def lane_change(name, step, direction="right"):
    return {"time": step * DT, "kind": "lane_change", "actors": [name], "direction": direction}


def collision(name, step):
    return {"time": step * DT, "kind": "collision", "actors": ["ego", name]}


# ------------------------------------------------------------------ binding


def test_the_cutter_plays_the_cut_in():
    result = check_story(CUT_IN, trace({"ego": ego_track(), "cutter": cut_in_car()},
                                       [lane_change("cutter", 30)]))
    assert result.played, result.missed


def test_a_traffic_car_ahead_does_not_stand_in_for_the_cutter():
    # the cutter drives by in its lane; a traffic car is in the ego's lane ahead all along
    stays = car(-10.0, lambda i: -3.5, 26.0)
    traffic = car(30.0, lambda i: 0.0, 20.0)
    result = check_story(CUT_IN, trace({"ego": ego_track(), "cutter": stays, "Car1": traffic},
                                       [lane_change("Car1", 3)]))
    assert not result.played
    assert [label for label, _ in result.missed] == ["cutter cut_in ahead_of ego within 3 s"]


def test_an_unnamed_story_actor_is_reported_with_the_fix():
    result = check_story(CUT_IN, trace({"ego": ego_track(), "Car1": cut_in_car()}, [lane_change("Car1", 30)]))
    assert len(result.missed) == 2
    assert 'with name "cutter"' in result.missed[0][1]


def test_story_actors_resolve_exactly_or_by_their_single_count_suffix():
    story = {"actors": {"cutter": "car", "walker": "pedestrian"}, "steps": [{"actor": "cutter", "action": "brake"}]}
    assert resolve_actors(story, ["ego", "cutter", "walker1"]) == {"ego": "ego", "cutter": "cutter",
                                                                   "walker": "walker1"}
    assert resolve_actors(story, ["ego", "walker1", "walker2"])["walker"] is None


def test_a_story_actor_of_another_kind_is_a_miss():
    story = {"actors": {"lead": "truck"}, "steps": [{"actor": "lead", "action": "keep_lane"}]}
    result = check_story(story, trace({"ego": ego_track(), "lead": car(30.0, lambda i: 0.0, 20.0)}))
    assert result.missed and "is a car" in result.missed[0][1]


# ------------------------------------------------------- relations at the event


def test_relations_are_read_at_the_event_not_at_the_start():
    # starts in the left lane, moves to the right lane while still behind, then passes on the right
    def y(i):
        return -3.5 if i < 5 else 3.5
    passer = car(-10.0, y, 26.0)
    story = {"actors": {"cutter": "car"},
             "steps": [{"actor": "cutter", "action": "overtake", "relations": [["left_of", "ego"]]}]}
    result = check_story(story, trace({"ego": ego_track(), "cutter": passer}))
    assert result.missed and "not left_of ego" in result.missed[0][1]
    story["steps"][0]["relations"] = [["right_of", "ego"]]
    assert check_story(story, trace({"ego": ego_track(), "cutter": passer})).played


def test_a_cut_in_behind_the_ego_is_no_cut_in():
    # the car slides into the ego's lane while still behind it, then falls back
    slow = cut_in_car(start_x=-15.0, speed=18.0, change_at=10)
    result = check_story(CUT_IN, trace({"ego": ego_track(), "cutter": slow}, [lane_change("cutter", 15)]))
    assert any(label.startswith("cutter cut_in") for label, _ in result.missed)


def test_steps_of_an_actor_play_in_order():
    # the cut-in comes first (the car is already ahead), the pass never happens after it
    ahead = cut_in_car(start_x=8.0, speed=21.0, change_at=5)
    result = check_story(CUT_IN, trace({"ego": ego_track(), "cutter": ahead}, [lane_change("cutter", 10)]))
    assert [label for label, _ in result.missed] == ["cutter overtake left_of ego"]


# ------------------------------------------------------------------- timing


def walker(x, start_step, speed=1.5, y0=6.0, direction=-1.0):
    """A pedestrian at x standing at y0 (right of the ego's lane), walking across from ``start_step``."""
    rows = []
    for i in range(N):
        walked = max(0, i - start_step) * DT * speed
        rows.append([x, y0 + direction * walked, -math.pi / 2, speed if i >= start_step else 0.0])
    return rows


CROSS = {"actors": {"walker": "pedestrian"},
         "steps": [{"actor": "walker", "action": "cross", "within_s": 3.0}]}


def test_a_crossing_in_front_of_the_ego_within_the_time_gap_counts():
    # ego at 20 m/s reaches x=130 at 6.5 s; the walker enters the lane (y 1.75) at about 5.5 s
    w = walker(130.0, start_step=13)
    assert check_story(CROSS, trace({"ego": ego_track(), "walker": w}, kinds={"walker": "pedestrian"})).played


def test_a_crossing_behind_the_ego_does_not_count():
    w = walker(60.0, start_step=20)  # the ego passed x=60 at 3 s
    result = check_story(CROSS, trace({"ego": ego_track(), "walker": w}, kinds={"walker": "pedestrian"}))
    assert result.missed and "never enters" not in result.missed[0][1]


def test_a_crossing_far_ahead_of_the_ego_is_out_of_the_time_gap():
    w = walker(190.0, start_step=0)  # enters the lane at about 2.8 s, 130 m (over 6 s) ahead
    result = check_story(CROSS, trace({"ego": ego_track(), "walker": w}, kinds={"walker": "pedestrian"}))
    assert result.missed and "s ahead of the ego" in result.missed[0][1]
    loose = {**CROSS, "steps": [{"actor": "walker", "action": "cross"}]}
    assert check_story(loose, trace({"ego": ego_track(), "walker": w}, kinds={"walker": "pedestrian"})).played


def test_an_ego_standing_short_of_the_crossing_is_within_the_gap():
    stopped = [[0.0, 0.0, 0.0, 0.0] for _ in range(N)]
    w = walker(8.0, start_step=5)
    assert check_story(CROSS, trace({"ego": stopped, "walker": w}, kinds={"walker": "pedestrian"})).played


def test_crossing_path_of_a_car_needs_it_to_enter_the_egos_path_ahead():
    story = {"actors": {"other": "car"},
             "steps": [{"actor": "other", "action": "keep_lane", "relations": [["crossing_path", "ego"]],
                        "within_s": 3.0}]}
    crosser = [[100.0, 20.0 - 10.0 * i * DT, -math.pi / 2, 10.0] for i in range(N)]
    assert check_story(story, trace({"ego": ego_track(), "other": crosser})).played
    long_after = [[30.0, 60.0 - 10.0 * i * DT, -math.pi / 2, 10.0] for i in range(N)]  # 4.5 s after the ego
    result = check_story(story, trace({"ego": ego_track(), "other": long_after}))
    assert result.missed and "4.5 s apart" in result.missed[0][1]


def test_a_car_crossing_just_behind_the_ego_crossed_its_path_but_a_walker_did_not():
    # the ego passes x=30 at 1.5 s; the other reaches the ego's line at 2 s (post-encroachment 0.5 s)
    story = {"actors": {"other": "car"},
             "steps": [{"actor": "other", "action": "keep_lane", "relations": [["crossing_path", "ego"]],
                        "within_s": 3.0}]}
    late = [[30.0, 20.0 - 10.0 * i * DT, -math.pi / 2, 10.0] for i in range(N)]
    assert check_story(story, trace({"ego": ego_track(), "other": late})).played
    walker_story = {"actors": {"other": "pedestrian"},
                    "steps": [{"actor": "other", "action": "cross", "relations": [["crossing_path", "ego"]],
                               "within_s": 3.0}]}
    slow = [[30.0, 4.5 - 1.5 * i * DT, -math.pi / 2, 1.5] for i in range(N)]  # in the lane at 1.8 s, behind
    assert not check_story(walker_story, trace({"ego": ego_track(), "other": slow},
                                               kinds={"other": "pedestrian"})).played


def _turning_ego_and_oncoming(shift_x: float):
    """An ego slowing into a left turn (heading 17 degrees into it) and an oncoming car going straight that strikes
    its front corner at step 26, the meeting point ``shift_x`` metres along the main road of the T-junction map."""
    ego, oncoming = [], []
    x, speed, heading = 40.5 + shift_x, 7.4, math.pi
    for i in range(N):
        if i > 20:
            speed, heading = max(0.9, speed * 0.7), min(heading + 0.05, math.pi + 0.3)
        ego.append([x, -1.8 + (0.0 if i <= 20 else min(1.1, 0.2 * (i - 20))), heading, speed] if i <= 26 else None)
        x -= speed * DT
        oncoming.append([-42.1 + shift_x + 8.4 * i * DT, 1.8, 0.0, 8.4] if i <= 26 else None)
    return {"ego": ego, "oncoming": oncoming}


def test_an_oncoming_car_that_strikes_the_turning_ego_in_the_junction_crossed_its_path():
    story = {"actors": {"oncoming": "car"},
             "steps": [{"actor": "oncoming", "action": "keep_lane",
                        "relations": [["crossing_path", "ego"]], "within_s": 3.0}]}
    params = {"map": "urban_t_junction.xodr"}
    in_junction = trace(_turning_ego_and_oncoming(0.0), events=[collision("oncoming", 26)])
    in_junction.params = params
    assert check_story(story, in_junction).played
    # the same near head-on collision 80 m down the main road, outside the junction, is no crossing
    on_the_road = trace(_turning_ego_and_oncoming(80.0), events=[collision("oncoming", 26)])
    on_the_road.params = params
    assert not check_story(story, on_the_road).played


# ---------------------------------------------------------- every actor


THREE = {"actors": {"walker_a": "pedestrian", "walker_b": "pedestrian", "walker_c": "pedestrian"},
         "steps": [{"actor": w, "action": "cross", "within_s": 4.0} for w in ("walker_a", "walker_b", "walker_c")]}


def test_three_walkers_need_three_crossings():
    kinds = {"walker_a": "pedestrian", "walker_b": "pedestrian", "walker_c": "pedestrian"}
    crossing = walker(130.0, start_step=13)
    standing = walker(130.0, start_step=N)  # never walks
    one = trace({"ego": ego_track(), "walker_a": crossing, "walker_b": standing, "walker_c": standing}, kinds=kinds)
    result = check_story(THREE, one)
    assert [label.split()[0] for label, _ in result.missed] == ["walker_b", "walker_c"]
    all_three = trace({"ego": ego_track(), "walker_a": crossing, "walker_b": walker(132.0, 13),
                       "walker_c": walker(128.0, 12)}, kinds=kinds)
    assert check_story(THREE, all_three).played


# --------------------------------------------------------------- collisions


def test_a_collision_counts_only_with_the_story_actor_after_its_manoeuvre_began():
    # the cutter has started sliding over (step 25 on) when the ego hits it at step 28
    cutter = cut_in_car()
    crash = trace({"ego": ego_track(n=29), "cutter": cutter[:29]}, [collision("cutter", 28)])
    result = check_story({"actors": {"cutter": "car"}, "steps": [CUT_IN["steps"][1]]}, crash)
    assert result.played and result.by_collision == ["cutter cut_in ahead_of ego within 3 s"]
    # hit before it began to move over: no credit
    early = trace({"ego": ego_track(n=20), "cutter": cutter[:20]}, [collision("cutter", 19)])
    assert not check_story({"actors": {"cutter": "car"}, "steps": [CUT_IN["steps"][1]]}, early).played
    # a bystander hit while the cutter moves over: no credit
    bystander = trace({"ego": ego_track(n=29), "cutter": cutter[:29], "Car1": car(10.0, lambda i: 0.0, 20.0)[:29]},
                      [collision("Car1", 28)])
    assert not check_story({"actors": {"cutter": "car"}, "steps": [CUT_IN["steps"][1]]}, bystander).played


def test_a_walker_that_walks_into_the_side_of_the_ego_did_not_cross():
    # the walker reaches the lane when the ego's front is already past it, and hits its side
    w = walker(43.0, start_step=0, speed=1.5, y0=5.0)  # lane edge reached at 2.2 s, the ego's centre at 44 m
    crash = trace({"ego": ego_track(n=13), "walker": w[:13]}, [collision("walker", 12)], kinds={"walker": "pedestrian"})
    result = check_story(CROSS, crash)
    assert not result.played and not result.by_collision


def test_a_lead_car_hit_while_braking_counts_as_braking():
    lead = [[30.0 + 20.0 * i * DT - (0.0 if i < 10 else 0.5 * (i - 10) ** 2 * DT * DT * 8), 0.0, 0.0,
             20.0 - (0.0 if i < 10 else 8.0 * (i - 10) * DT)] for i in range(13)]
    story = {"actors": {"lead": "car"}, "steps": [{"actor": "lead", "action": "brake"}]}
    crash = trace({"ego": ego_track(n=13), "lead": lead}, [collision("lead", 12)])
    assert check_story(story, crash).played  # speed fell 3.2 m/s in 0.4 s before the hit
    calm = [[30.0 + 20.0 * i * DT, 0.0, 0.0, 20.0] for i in range(13)]
    assert not check_story(story, trace({"ego": ego_track(n=13), "lead": calm}, [collision("lead", 12)])).played


# ---------------------------------------------------------- hold, ego, format


def test_hold_needs_the_state_to_last_to_the_end():
    story = {"actors": {"truck": "truck"}, "steps": [{"actor": "truck", "action": "stop", "hold": True}]}
    parked = [[80.0, 0.0, 0.0, 0.0] for _ in range(N)]
    assert check_story(story, trace({"ego": ego_track(), "truck": parked}, kinds={"truck": "truck"})).played
    drives_off = [[80.0 + (0.0 if i < 20 else 5.0 * (i - 20) * DT), 0.0, 0.0, 0.0 if i < 20 else 5.0]
                  for i in range(N)]
    result = check_story(story, trace({"ego": ego_track(), "truck": drives_off}, kinds={"truck": "truck"}))
    assert result.missed and "last to the end" in result.missed[0][1]


def test_ego_steps_are_required_only_of_the_scripts_own_ego():
    story = {"actors": {"lead": "car"}, "steps": [{"actor": "ego", "action": "brake"},
                                                   {"actor": "lead", "action": "keep_lane"}]}
    t = trace({"ego": ego_track(), "lead": car(30.0, lambda i: 0.0, 20.0)})
    assert check_story(story, t, ego="idm").played
    assert [label for label, _ in check_story(story, t, ego="scenic").missed] == ["ego brake"]


def test_when_reads_a_step_at_the_moment_of_another_actors_step():
    # the obstacle is within 2 s ahead of the ego from about 6 s on; the blocker is to the ego's left then,
    # unless it moved over to the right lane at 3 s
    story = {"actors": {"obstacle": "obstacle", "blocker": "car"},
             "steps": [{"actor": "obstacle", "action": "stop", "relations": [["same_lane", "ego"]], "within_s": 2.0},
                       {"actor": "blocker", "action": "keep_lane", "relations": [["left_of", "ego"]],
                        "when": "obstacle"}]}
    kinds = {"obstacle": "obstacle"}
    load = [[160.0, 0.0, 0.0, 0.0] for _ in range(N)]
    beside = car(0.0, lambda i: -3.5, 20.0)
    assert check_story(story, trace({"ego": ego_track(), "obstacle": load, "blocker": beside}, kinds=kinds)).played
    moved = car(0.0, lambda i: -3.5 if i < 15 else 3.5, 20.0)
    result = check_story(story, trace({"ego": ego_track(), "obstacle": load, "blocker": moved}, kinds=kinds))
    assert [label for label, _ in result.missed] == ["blocker keep_lane left_of ego when obstacle does"]


@pytest.mark.parametrize("story, message", [
    ({"steps": []}, "actors"),
    ({"actors": {"ego": "car"}, "steps": [{"actor": "ego", "action": "brake"}]}, "not 'ego'"),
    ({"actors": {"cutter": "lorry"}, "steps": [{"actor": "cutter", "action": "brake"}]}, "unknown kind"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cuter", "action": "brake"}]}, "not 'ego' nor listed"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cutter", "action": "jump"}]}, "vocabulary"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cutter", "action": "brake",
                                              "relations": [["ahead", "ego"]]}]}, "[relation, other]"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cutter", "action": "brake", "within_s": 0}]}, "within_s"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cutter", "action": "brake", "at": 1}]}, "unknown keys"),
    ({"actors": {"cutter": "car"}, "steps": [{"actor": "cutter", "action": "brake", "when": "cutter"}]},
     "another story actor"),
])
def test_a_malformed_story_is_refused_with_the_fix(story, message):
    with pytest.raises(StoryError, match=message.replace("[", r"\[").replace("]", r"\]")):
        normalize_story(story)
