"""Trace semantics for the sg-compose actions (u_turn, reverse, swerve, pull_out) and kinds (bus, motorcycle,
bicycle), on synthetic traces on the shipped two-way urban road (eastbound y = 1.75, westbound y = -1.75;
highway-env frame: heading 0 drives +x, growing heading turns right)."""

import math

from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from envs.trace import EpisodeTrace

DT = 0.2
MAP = "urban_two_way"


def _trace(tracks, kinds=None, events=()):
    steps = min(len(rows) for rows in tracks.values())
    states = [{name: rows[i] for name, rows in tracks.items()} for i in range(steps)]
    return EpisodeTrace(scenario="t", source="", seed=0, scene_seed=0, params={"map": f"/x/{MAP}.xodr"},
                        config={"policy_frequency": 5}, states=states, events=list(events), kinds=kinds or {})


def _straight(x0, speed, steps=60, y=1.75, heading=0.0):
    sign = 1.0 if abs(heading) < 1 else -1.0
    return [[x0 + sign * speed * DT * i, y, heading, speed] for i in range(steps)]


def _actions(elements, kind):
    return {a for k, a in elements.actions if k == kind}


def _u_turn(x0=0.0, speed=4.0, steps=60):
    """East along y = 1.75, a half circle to the left (heading falling to -pi), back west along y = -1.75."""
    rows, x, y, h = [], x0, 1.75, 0.0
    radius = 1.75
    for i in range(steps):
        rows.append([x, y, h, speed])
        if 15 <= i < 15 + int(math.pi * radius / (speed * DT)) + 1 and h > -math.pi:
            h = max(-math.pi, h - speed * DT / radius)
        x += speed * DT * math.cos(h)
        y += speed * DT * math.sin(h)
    return rows


def test_u_turn_is_detected_and_replaces_the_turn():
    ego = _straight(-40.0, 6.0)
    car = _u_turn(0.0)
    el = elements_from_trace(_trace({"ego": ego, "car1": car}))
    acts = _actions(el, "car")
    assert "u_turn" in acts
    assert not acts & {"turn_left", "turn_right", "keep_lane"}
    assert "u_turn" not in _actions(el, "ego")


def test_reverse_is_detected_for_a_car_backing_up():
    ego = _straight(-40.0, 0.0)
    car = [[10.0 - 1.0 * DT * i, 1.75, 0.0, -1.0] for i in range(40)]  # 8 m backwards, heading east
    el = elements_from_trace(_trace({"ego": ego, "car1": car}))
    assert "reverse" in _actions(el, "car")
    assert "reverse" not in _actions(el, "ego")


def test_swerve_out_and_back_without_a_lane_change():
    ego = _straight(0.0, 8.0)
    # sideways bump of 1.4 m between steps 20 and 40, back on the lane centre afterwards
    ego = [[x, 1.75 + 1.4 * math.sin(math.pi * (i - 20) / 20) if 20 <= i <= 40 else 1.75, h, v]
           for i, (x, _y, h, v) in enumerate(ego)]
    el = elements_from_trace(_trace({"ego": ego}))
    assert "swerve" in _actions(el, "ego")
    straight = elements_from_trace(_trace({"ego": _straight(0.0, 8.0)}))
    assert "swerve" not in _actions(straight, "ego")


def test_a_lane_change_event_is_not_a_swerve():
    ego = _straight(0.0, 8.0)
    ego = [[x, 1.75 + 1.4 * math.sin(math.pi * (i - 20) / 20) if 20 <= i <= 40 else 1.75, h, v]
           for i, (x, _y, h, v) in enumerate(ego)]
    event = {"kind": "lane_change", "actors": ["ego"], "time": 4.0, "direction": "left"}
    el = elements_from_trace(_trace({"ego": ego}, events=[event]))
    assert "swerve" not in _actions(el, "ego")


def test_pull_out_from_the_shoulder():
    ego = _straight(-30.0, 6.0)
    car = []
    for i in range(60):
        if i < 10:
            car.append([20.0, 4.5, 0.0, 0.0])  # parked on the right shoulder (y grows to the right)
        else:
            t = min(1.0, (i - 10) / 20)
            x = 20.0 + 4.0 * DT * (i - 10)
            car.append([x, 4.5 - 2.75 * t, 0.0, 4.0])
    el = elements_from_trace(_trace({"ego": ego, "car1": car}))
    acts = _actions(el, "car")
    assert "pull_out" in acts
    assert "swerve" not in acts
    moving_off = [[20.0 + 4.0 * DT * max(0, i - 10), 1.75, 0.0, 0.0 if i < 10 else 4.0] for i in range(60)]
    el = elements_from_trace(_trace({"ego": ego, "car1": moving_off}))
    assert "pull_out" not in _actions(el, "car")


def test_new_kinds_come_from_the_trace_kinds():
    ego = _straight(-20.0, 8.0)
    tracks = {"ego": ego, "v1": _straight(0.0, 8.0), "v2": _straight(20.0, 4.0, y=-1.75, heading=math.pi),
              "v3": _straight(10.0, 12.0)}
    kinds = {"v1": "bus", "v2": "bicycle", "v3": "motorcycle"}
    el = elements_from_trace(_trace(tracks, kinds=kinds))
    assert {"bus", "bicycle", "motorcycle"} <= set(el.participants)
    assert "keep_lane" in _actions(el, "bus")
    assert "oncoming" in {r for k, r, o in el.relations if k == "bicycle"}


def test_ego_overtaking_a_bus_is_judged():
    bus = _straight(0.0, 5.0)
    ego = [[-15.0 + 10.0 * DT * i, 1.75 if i < 10 else 5.25, 0.0, 10.0] for i in range(60)]
    event = {"kind": "lane_change", "actors": ["ego"], "time": 2.0, "direction": "right"}
    el = elements_from_trace(_trace({"ego": ego, "b": bus}, kinds={"b": "bus"}, events=[event]))
    assert "overtake" in _actions(el, "ego")


def test_bypass_into_the_oncoming_lane_is_an_overtake_without_a_lane_change_event():
    box = [[30.0, 1.75, 0.0, 0.0]] * 60
    ego = [[8.0 * DT * i, 1.75 if abs(8.0 * DT * i - 30.0) > 12 else -1.75, 0.0, 8.0] for i in range(60)]
    el = elements_from_trace(_trace({"ego": ego, "obstacle1": box}, kinds={"obstacle1": "obstacle"}))
    assert "overtake" in _actions(el, "ego")
    close = [[8.0 * DT * i, 1.75 if abs(8.0 * DT * i - 30.0) > 12 else 0.5, 0.0, 8.0] for i in range(60)]
    el = elements_from_trace(_trace({"ego": close, "obstacle1": box}, kinds={"obstacle1": "obstacle"}))
    assert "overtake" not in _actions(el, "ego")
