"""What a failure's behaviour says (``dv2s_gym.mining.behaviour``) on hand-made traces, and the behaviour
clusters built from it (``dv2s_gym.mining.cluster``)."""

from __future__ import annotations

import math
from types import SimpleNamespace

from dv2s_gym.mining.behaviour import UNKNOWN, Behaviour, extract_behaviour
from dv2s_gym.mining.cluster import cell_id, cluster_failures, cluster_id, pair_of
from dv2s_gym.mining.monitors import Failure
from scenario_bank.records import EpisodeRecord

FREQUENCY = 5  # steps per second


def _trace(paths: dict, kinds: dict | None = None) -> SimpleNamespace:
    """A trace whose states follow ``paths`` (actor -> function of the step giving [x, y, heading, speed])."""
    steps = 21
    states = [{name: [float(v) for v in path(step)] for name, path in paths.items()} for step in range(steps)]
    return SimpleNamespace(states=states, kinds=kinds or {}, config={"policy_frequency": FREQUENCY})


def _cruise(y: float, speed: float, x0: float = 0.0):
    return lambda step: [x0 + speed * step / FREQUENCY, y, 0.0, speed]


def _collision(with_: str = "car1", kind: str = "car", step: int = 20) -> Failure:
    return Failure(type="collision", time=step / FREQUENCY, step=step, with_=with_, with_kind=kind,
                   collision_type="rear_end")


def test_a_braking_lead_car_hit_by_a_lane_keeping_ego():
    # car1 drives at 20 m/s, then brakes at 7.5 m/s^2 in the last two seconds
    speed = lambda s: 20.0 - 1.5 * max(0, s - 10)  # noqa: E731
    trace = _trace({"ego": _cruise(0.0, 25.0),
                    "car1": lambda s: [40.0 + sum(speed(k) for k in range(s)) / FREQUENCY, 0.0, 0.0, speed(s)]})
    assert extract_behaviour(trace, _collision()) == Behaviour(actor="car", actor_manoeuvre="braking",
                                                               ego_manoeuvre="keeping_lane")


def test_a_car_cutting_in_from_the_next_lane():
    # car1 drives in the lane at y = 4 and moves into the ego's lane (y = 0) ahead of it in the last two seconds
    trace = _trace({"ego": _cruise(0.0, 25.0),
                    "car1": lambda s: [30.0 + 22.0 * s / FREQUENCY, max(0.0, 4.0 - 0.4 * max(0, s - 10)), 0.0, 22.0]})
    assert extract_behaviour(trace, _collision()).actor_manoeuvre == "cut_in"


def test_a_car_leaving_the_ego_s_lane_is_a_lane_change_not_a_cut_in():
    trace = _trace({"ego": _cruise(0.0, 25.0),
                    "car1": lambda s: [10.0 + 22.0 * s / FREQUENCY, min(4.0, 0.4 * max(0, s - 10)), 0.0, 22.0]})
    assert extract_behaviour(trace, _collision()).actor_manoeuvre == "lane_change"


def test_a_crossing_pedestrian_and_an_oncoming_car():
    walker = _trace({"ego": _cruise(0.0, 10.0), "ped": lambda s: [40.0, -5.0 + 0.3 * s, math.pi / 2, 1.5]},
                    {"ped": "pedestrian"})
    behaviour = extract_behaviour(walker, _collision("ped", None))
    assert behaviour == Behaviour(actor="pedestrian", actor_manoeuvre="crossing", ego_manoeuvre="keeping_lane")
    oncoming = _trace({"ego": _cruise(0.0, 10.0), "car2": lambda s: [80.0 - 3.0 * s, 0.0, math.pi, 15.0]})
    assert extract_behaviour(oncoming, _collision("car2")).actor_manoeuvre == "oncoming"


def test_a_stopped_obstacle_and_an_ego_changing_lanes_or_braking():
    stopped = {"car1": lambda s: [60.0, 4.0, 0.0, 0.0]}
    swerving = _trace({"ego": lambda s: [5.0 * s, 0.4 * max(0, s - 10), 0.0, 25.0], **stopped})
    assert extract_behaviour(swerving, _collision()) == Behaviour(actor="car", actor_manoeuvre="stopped",
                                                                  ego_manoeuvre="lane_change")
    braking = _trace({"ego": lambda s: [4.0 * s, 4.0, 0.0, 25.0 - s], **stopped})
    assert extract_behaviour(braking, _collision()).ego_manoeuvre == "braking"


def test_failures_without_another_actor():
    stalled = _trace({"ego": lambda s: [10.0, 0.0, 0.0, 0.0], "car1": _cruise(4.0, 20.0)})
    stall = Failure(type="stall", time=1.0, step=5)
    assert extract_behaviour(stalled, stall) == Behaviour(actor="none", actor_manoeuvre="none", ego_manoeuvre="stopped")
    assert extract_behaviour(stalled, None) is None
    empty = SimpleNamespace(states=[], kinds={}, config={})
    assert extract_behaviour(empty, stall) == UNKNOWN


def test_a_stall_names_the_car_the_ego_stood_behind_in_its_lane():
    # the ego stands at x = 10; a car stopped 55 m ahead in its lane (beyond the stall's 40 m free path), another
    # car cruising in the next lane: the stall is clustered with the stopped car, not with "none"
    stall = Failure(type="stall", time=1.0, step=5)
    behind = _trace({"ego": lambda s: [10.0, 0.0, 0.0, 0.0], "car1": lambda s: [65.0, 0.5, 0.0, 0.0],
                     "car2": _cruise(4.0, 20.0, x0=20.0)}, {"car1": "truck"})
    assert extract_behaviour(behind, stall) == Behaviour(actor="truck", actor_manoeuvre="stopped",
                                                         ego_manoeuvre="stopped")
    slowing = _trace({"ego": lambda s: [10.0, 0.0, 0.0, 0.0],
                      "car1": lambda s: [60.0 + 0.2 * s, 0.0, 0.0, max(1.0, 8.0 - 2.0 * s)]})
    assert extract_behaviour(slowing, stall) == Behaviour(actor="car", actor_manoeuvre="braking",
                                                          ego_manoeuvre="stopped")
    too_far = _trace({"ego": lambda s: [10.0, 0.0, 0.0, 0.0], "car1": lambda s: [10.0 + 85.0, 0.0, 0.0, 0.0]})
    assert extract_behaviour(too_far, stall).actor == "none"  # beyond WAITING_DISTANCE (80 m): a free road
    records = [_record(0, "s", "stall", tuple(extract_behaviour(behind, stall).to_dict().values()), [0.5])]
    assert cluster_failures(records)[0] == "s/stall/truck-stopped/ego-stopped"


def _record(index: int, scenario: str, kind: str, behaviour, point) -> EpisodeRecord:
    record = {"index": index, "scenario": scenario, "family": scenario, "seed": index,
              "failure": {"type": kind.split(":")[0], "kind": kind}, "point": point, "error": None}
    if behaviour:
        record["behaviour"] = dict(zip(("actor", "actor_manoeuvre", "ego_manoeuvre"), behaviour))
    return EpisodeRecord.from_dict(record)


def test_clusters_are_behaviours_not_parameter_cells():
    records = [
        _record(0, "cut_in", "collision:rear_end", ("car", "braking", "keeping_lane"), [0.1]),
        _record(1, "cut_in", "collision:rear_end", ("car", "braking", "keeping_lane"), [0.9]),  # other cell, same
        _record(2, "cut_in", "collision:rear_end", ("car", "cut_in", "keeping_lane"), [0.1]),   # same cell, other
        _record(3, "cut_in", "stall", ("none", "none", "stopped"), [0.5]),
        EpisodeRecord.from_dict({"index": 4, "scenario": "cut_in", "seed": 4, "failure": None, "error": None}),
    ]
    clusters = cluster_failures(records)
    assert clusters[0] == clusters[1] == "cut_in/collision:rear_end/car-braking/ego-keeping_lane"
    assert clusters[2] == "cut_in/collision:rear_end/car-cut_in/ego-keeping_lane"
    assert clusters[3] == "cut_in/stall/none-none/ego-stopped" and 4 not in clusters
    assert all(c.split("/")[:2] == pair_of(records[i]).split("/") for i, c in clusters.items())
    assert cell_id(records[0]) == cell_id(records[2]) != cell_id(records[1])  # novelty feedback's cells
    assert cluster_id(_record(5, "a", "off_road", None, [])) == "a/off_road/unknown-unknown/ego-unknown"
