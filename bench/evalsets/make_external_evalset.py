"""Build the external evaluation set: clips rendered by stock highway-env, scripted and labelled by hand.

The in-house set (:mod:`bench.evalsets.make_evalset`) renders the project's own
bank scenarios in the project's own env. This set does not: every clip is an
episode of a stock highway-env environment (``highway-v0``, ``merge-v0``,
``intersection-v0``, ``roundabout-v0``) rendered by highway-env's own viewer. After
``reset`` the stock traffic is replaced by scripted actors placed through
highway-env's API (:meth:`IDMVehicle.make_on_lane`, ``target_speed``,
``target_lane_index``, :meth:`plan_route_to`, :class:`Obstacle`); the ego is an
:class:`IDMVehicle` too (painted in highway-env's ego green), so it keeps its
distance like a driver, on a scripted lane and route.

The later scripts (``cls_*``, ``stock_*``, ``rb_two_cars_pass_entry``) bring what the first ones did not
show: stock vehicle classes drawn in the colours highway-env gives them (no colour set: ``LinearVehicle``
and its Aggressive/Defensive subclasses yellow, ``IDMVehicle`` blue, ``MDPVehicle`` green), a 10 m vehicle,
other ``scaling`` values and screen sizes (:attr:`Script.scaling`, :attr:`Script.size`), a roundabout with
two cars, and highway-v0's own traffic kept as ``reset`` made it (:attr:`Script.stock_traffic`).

Each :class:`Script` carries, written by hand, the label of what it scripts
(elements in the vocabulary of :mod:`scenario_bank.elements`) and a reference
description. Nothing of the project reads the clips to make the labels. The only
check made while building is on highway-env's own vehicle state: the clip is
refused (an error, not a skip) when its scripted event did not happen as
scripted, e.g. when the cut-in car never reached the ego's lane or a car crashed
that the script did not make crash.

Labelling conventions (those of the in-house labels): ``participants`` names
every vehicle placed; actions and relations are those of the actors the script
gives a story to, relations taken where the actor starts; the ego's own speed
changes in reaction to others are not labelled (its lane changes, turns and
crossing a junction are).

Command line::

    python -m bench.evalsets.make_external_evalset OUT_DIR [--only NAME ...]

writes ``OUT_DIR/<script>_v<k>.webm`` and ``<script>_v<k>.label.json`` (the format ``dv2s eval``
reads). The set lives in ``bench/evalsets/highway_env/`` (:data:`EXTERNAL_EVALSET_DIR`), whose
README (written by hand) lists the scripts and the measured results.
Deterministic: fixed seeds, fixed variants; no randomness beyond highway-env's seeded reset.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple


# highway-env's viewer draws nothing under SDL's "dummy" driver: render offscreen.
if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
    os.environ["SDL_VIDEODRIVER"] = "offscreen"
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

__all__ = ["EXTERNAL_EVALSET_DIR", "SCRIPTS", "Script", "Scene", "render_script", "build", "main"]

EXTERNAL_EVALSET_DIR = Path(__file__).resolve().parent / "highway_env"
"""The shipped external evaluation set (stock highway-env clips, labelled by hand)."""

FPS = 5
SIZE = 480
SCALING = 5.5
VARIANTS = (0, 1, 2)


@dataclass
class Script:
    """One scripted situation: a stock env, a scene builder and its hand-written label."""

    name: str
    env_id: str
    use_case: str
    description: str
    elements: Dict[str, Any]
    scene: Callable[[Any, int], "Scene"]
    seconds: float = 10.0
    scaling: float = SCALING                  # highway-env's viewer scale, px per m
    size: Tuple[int, int] = (SIZE, SIZE)      # screen width, height (px)
    stock_traffic: int = 0                    # >0: keep this many vehicles of the env's own traffic


@dataclass
class Scene:
    """What a scene builder returns: the ego, the actors, timed events and the post-hoc check."""

    ego: Any
    actors: Dict[str, Any]
    events: List[Tuple[Any, Callable[[], None]]]  # (time in s, or a predicate of the scene, action)
    check: Callable[["Record"], Optional[str]]
    crash_expected: bool = False


@dataclass
class Record:
    """Per-step state of every vehicle, from highway-env (lane index, position, speed, heading, crashed)."""

    steps: List[Dict[str, Dict[str, Any]]]

    def lanes(self, name: str) -> List[Any]:
        return [s[name]["lane"] for s in self.steps]

    def speeds(self, name: str) -> List[float]:
        return [s[name]["speed"] for s in self.steps]

    def headings(self, name: str) -> List[float]:
        return [s[name]["heading"] for s in self.steps]


# ----------------------------------------------------------------------------- helpers
def _car(road, lane_index, s: float, speed: float, target_speed: Optional[float] = None,
         destination: Optional[str] = None, ego: bool = False):
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.graphics import VehicleGraphics

    v = IDMVehicle.make_on_lane(road, lane_index, longitudinal=s, speed=speed)
    v.enable_lane_change = False
    v.target_speed = speed if target_speed is None else target_speed
    if destination:
        v.plan_route_to(destination)
    if ego:
        v.color = VehicleGraphics.EGO_COLOR
    road.vehicles.append(v)
    return v


def _vehicle(cls, road, lane_index, s: float, speed: float, target_speed: Optional[float] = None,
             destination: Optional[str] = None, length: Optional[float] = None):
    """A stock highway-env vehicle of class ``cls`` (IDMVehicle, LinearVehicle, AggressiveVehicle, ...),
    no lane changes of its own, drawn in the colour highway-env gives its class (no colour set).
    ``length`` makes a long vehicle (highway-env draws it as a longer rectangle of its class colour)."""
    v = cls.make_on_lane(road, lane_index, longitudinal=s, speed=speed)
    if length is not None:
        v.LENGTH = float(length)
        v.diagonal = float((v.LENGTH ** 2 + v.WIDTH ** 2) ** 0.5)
    v.enable_lane_change = False
    v.target_speed = speed if target_speed is None else target_speed
    if destination:
        v.plan_route_to(destination)
    road.vehicles.append(v)
    return v


def _mdp_ego(road, lane_index, s: float, speed: float):
    """The ego as highway-env's own controlled vehicle (MDPVehicle, green by its class): it keeps its lane
    and speed under the IDLE action; scripted events call ``ego.act("LANE_LEFT")`` and the like."""
    from highway_env.vehicle.controller import MDPVehicle

    v = MDPVehicle.make_on_lane(road, lane_index, longitudinal=s, speed=speed)
    v.target_speed = speed
    road.vehicles.append(v)
    return v


def _obstacle(road, lane_index, s: float):
    from highway_env.vehicle.objects import Obstacle

    lane = road.network.get_lane(lane_index)
    o = Obstacle(road, lane.position(s, 0.0), heading=lane.heading_at(s))
    road.objects.append(o)
    return o


def _set(obj, **attrs) -> Callable[[], None]:
    def apply() -> None:
        for k, v in attrs.items():
            setattr(obj, k, v)
    return apply


def _lane_ids(rec: Record, name: str) -> List[int]:
    return [lane[2] for lane in rec.lanes(name)]


def _turn_deg(rec: Record, name: str) -> float:
    """Heading change over the clip, left turns positive (highway-env's heading grows clockwise on screen)."""
    import math

    h = rec.headings(name)
    d = h[0] - h[-1]
    return math.degrees((d + math.pi) % (2 * math.pi) - math.pi)


def _ahead_at_end(rec: Record, name: str) -> bool:
    """Whether ``name`` ends the clip ahead of the ego (along the ego's final heading)."""
    import math

    e, a = rec.steps[-1]["ego"], rec.steps[-1][name]
    return (a["x"] - e["x"]) * math.cos(e["heading"]) + (a["y"] - e["y"]) * math.sin(e["heading"]) > 0


def _require(condition: bool, message: str) -> Optional[str]:
    return None if condition else message


# ----------------------------------------------------------------------------- highway-v0
HW = ("0", "1")


def _hw_lead_brakes(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, (*HW, 1), 200.0, 25.0, ego=True)
    lead = _car(road, (*HW, 1), 200.0 + 28 + 4 * k, 25.0)
    side = _car(road, (*HW, 2), 200.0 - 10 + 5 * k, 24.0)
    return Scene(ego, {"lead": lead, "side": side}, [(2.0 + 0.4 * k, _set(lead, target_speed=6.0 + 2 * k))],
                 lambda r: _require(min(r.speeds("lead")) < 12.0, "the lead car did not brake"))


def _hw_lead_stopped(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, (*HW, 2), 200.0, 20.0 + 2 * k, ego=True)
    stopped = _car(road, (*HW, 2), 200.0 + 70 + 10 * k, 0.0, target_speed=0.0)
    return Scene(ego, {"stopped": stopped}, [],
                 lambda r: _require(max(r.speeds("stopped")) < 0.5, "the stopped car moved"))


def _hw_cut_in(side: int) -> Callable[[Any, int], Scene]:
    def scene(env, k: int) -> Scene:
        road = env.road
        ego = _car(road, (*HW, 1), 200.0, 22.0, ego=True)
        cutter = _car(road, (*HW, 1 + side), 200.0 + 4 + 3 * k, 27.0)
        return Scene(ego, {"cutter": cutter}, [(1.6 + 0.4 * k, _set(cutter, target_lane_index=(*HW, 1)))],
                     lambda r: _require(_lane_ids(r, "cutter")[-1] == 1 and _ahead_at_end(r, "cutter"),
                                        "the car did not cut in ahead of the ego"))
    return scene


def _hw_overtaken(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, (*HW, 2), 200.0, 20.0, ego=True)
    fast = _car(road, (*HW, 1), 200.0 - 25 - 5 * k, 30.0 + k)
    return Scene(ego, {"fast": fast}, [],
                 lambda r: _require(r.steps[-1]["fast"]["x"] > r.steps[-1]["ego"]["x"] + 5, "the car did not pass"))


def _hw_ego_passes_slow_car(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, (*HW, 2), 200.0, 25.0, ego=True)
    slow = _car(road, (*HW, 2), 200.0 + 35 + 5 * k, 15.0)
    return Scene(ego, {"slow": slow}, [(1.0 + 0.4 * k, _set(ego, target_lane_index=(*HW, 1)))],
                 lambda r: _require(_lane_ids(r, "ego")[-1] == 1, "the ego did not change lanes"))


def _hw_obstacle(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, (*HW, 1), 200.0, 20.0, ego=True)
    obstacle = _obstacle(road, (*HW, 1), 200.0 + 60 + 5 * k)
    near = lambda: obstacle.position[0] - ego.position[0] < 25.0 + 3 * k
    return Scene(ego, {}, [(near, _set(ego, target_lane_index=(*HW, 0)))],
                 lambda r: _require(_lane_ids(r, "ego")[-1] == 0, "the ego did not steer around the obstacle"))


# ----------------------------------------------------------------------------- merge-v0
def _merge_from_ramp(ego_lane: int) -> Callable[[Any, int], Scene]:
    def scene(env, k: int) -> Scene:
        road = env.road
        ego = _car(road, ("a", "b", ego_lane), 100.0 + 4 * k, 22.0, ego=True)
        ramp = _car(road, ("j", "k", 0), 130.0, 20.0)
        on_lane = lambda: ramp.lane_index[0] == "b" and ramp.lane.local_coordinates(ramp.position)[0] > 10 + 8 * k
        events = [(on_lane, _set(ramp, target_lane_index=("b", "c", 1)))]
        return Scene(ego, {"ramp": ramp}, events,
                     lambda r: _require(r.lanes("ramp")[-1][2] == 1 and r.lanes("ramp")[-1][0] in ("b", "c")
                                        and _ahead_at_end(r, "ramp"), "the ramp car did not merge ahead of the ego"))
    return scene


# ----------------------------------------------------------------------------- intersection-v0
def _ix_left_turn_oncoming(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("o0", "ir0", 0), 60.0 - 2 * k, 7.0, destination="o1", ego=True)
    oncoming = _car(road, ("o2", "ir2", 0), 80.0 + 2 * k, 9.0, destination="o0")
    return Scene(ego, {"oncoming": oncoming}, [],
                 lambda r: _require(_turn_deg(r, "ego") > 60 and abs(_turn_deg(r, "oncoming")) < 20,
                                    "the ego did not turn left or the oncoming car turned"))


def _ix_crossing(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("o0", "ir0", 0), 65.0, 7.0, destination="o2", ego=True)
    crosser = _car(road, ("o3", "ir3", 0), 80.0 + 2 * k, 9.0, destination="o1")
    return Scene(ego, {"crosser": crosser}, [],
                 lambda r: _require(abs(_turn_deg(r, "ego")) < 20 and abs(_turn_deg(r, "crosser")) < 20,
                                    "someone turned"))


def _ix_right_turn_into_path(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("o0", "ir0", 0), 80.0, 5.0, destination="o2", ego=True)
    turner = _car(road, ("o3", "ir3", 0), 86.0 + 2 * k, 7.0, destination="o2")
    return Scene(ego, {"turner": turner}, [],
                 lambda r: _require(_turn_deg(r, "turner") < -60, "the car did not turn right"))


def _ix_oncoming_left_turn(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("o0", "ir0", 0), 80.0, 3.0, destination="o2", ego=True)
    turner = _car(road, ("o2", "ir2", 0), 80.0 + 2 * k, 8.0, destination="o3")
    return Scene(ego, {"turner": turner}, [],
                 lambda r: _require(_turn_deg(r, "turner") > 60, "the oncoming car did not turn left"))


def _ix_ego_right_turn(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("o0", "ir0", 0), 70.0 + 3 * k, 7.0, destination="o3", ego=True)
    return Scene(ego, {}, [], lambda r: _require(_turn_deg(r, "ego") < -60, "the ego did not turn right"))


# ----------------------------------------------------------------------------- roundabout-v0
def _exits_north(rec: Record) -> bool:
    """The ego left by the opposite (north) exit and drives straight again by the clip's end."""
    return rec.lanes("ego")[-1][:2] in (("nx", "nxs"), ("nxs", "nxr")) and abs(_turn_deg(rec, "ego")) < 15


def _rb_enters_ahead(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("ser", "ses", 0), 115.0 + 2 * k, 8.0, destination="nxr", ego=True)
    circling = _car(road, ("we", "sx", 0), 8.0 + 2 * k, 8.0, destination="exr")
    return Scene(ego, {"circling": circling}, [],
                 lambda r: _require(_exits_north(r) and any(l[0] in ("se", "ex") for l in r.lanes("circling")),
                                    "the ego did not drive through or the car left early"))


def _rb_car_enters(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("ser", "ses", 0), 115.0, 8.0, destination="nxr", ego=True)
    entering = _car(road, ("eer", "ees", 0), 88.0 + 3 * k, 8.0, destination="wxr")
    return Scene(ego, {"entering": entering}, [],
                 lambda r: _require(_exits_north(r) and any(l[0] in ("ee", "nx", "ne") for l in r.lanes("entering")),
                                    "the ego did not drive through or the car did not enter the ring"))


def _rb_first_exit(env, k: int) -> Scene:
    road = env.road
    ego = _car(road, ("ser", "ses", 0), 105.0 + 3 * k, 8.0, destination="exr", ego=True)
    lead = _car(road, ("ser", "ses", 0), 125.0 + 3 * k, 8.0, destination="exr")
    return Scene(ego, {"lead": lead}, [],
                 lambda r: _require(_turn_deg(r, "ego") < -60 and _turn_deg(r, "lead") < -60, "no right turn"))


# ----------------------------------------------------------------------------- stock classes, scales, traffic
def _cls_linear_cut_in(env, k: int) -> Scene:
    """MDPVehicle ego (green by class), a LinearVehicle (yellow) cuts in from the left; a Defensive one drives
    far ahead on the right."""
    from highway_env.vehicle.behavior import DefensiveVehicle, LinearVehicle

    road = env.road
    ego = _mdp_ego(road, (*HW, 1), 200.0, 25.0)
    cutter = _vehicle(LinearVehicle, road, (*HW, 0), 200.0 + 5 + 3 * k, 30.0)
    _vehicle(DefensiveVehicle, road, (*HW, 3), 200.0 + 90 + 5 * k, 22.0)
    return Scene(ego, {"cutter": cutter}, [(1.4 + 0.4 * k, _set(cutter, target_lane_index=(*HW, 1)))],
                 lambda r: _require(_lane_ids(r, "cutter")[-1] == 1 and _ahead_at_end(r, "cutter"),
                                    "the car did not cut in ahead of the ego"))


def _cls_truck_lead_brakes(env, k: int) -> Scene:
    """A 10 m IDMVehicle (blue, long) brakes ahead of the ego; an AggressiveVehicle (yellow) drives on the
    right."""
    from highway_env.vehicle.behavior import AggressiveVehicle, IDMVehicle

    road = env.road
    ego = _car(road, (*HW, 1), 200.0, 24.0, ego=True)
    truck = _vehicle(IDMVehicle, road, (*HW, 1), 200.0 + 30 + 3 * k, 24.0, length=10.0)
    side = _vehicle(AggressiveVehicle, road, (*HW, 2), 200.0 - 6 + 4 * k, 23.0)
    return Scene(ego, {"truck": truck, "side": side}, [(2.0 + 0.4 * k, _set(truck, target_speed=6.0 + 2 * k))],
                 lambda r: _require(min(r.speeds("truck")) < 12.0, "the truck did not brake"))


def _cls_lead_stopped_yellow(env, k: int) -> Scene:
    """A LinearVehicle (yellow) stands in the ego's lane; the ego (green IDM) stops behind it."""
    from highway_env.vehicle.behavior import LinearVehicle

    road = env.road
    ego = _car(road, (*HW, 2), 200.0, 17.0 + k, ego=True)
    stopped = _vehicle(LinearVehicle, road, (*HW, 2), 200.0 + 60 + 8 * k, 0.0, target_speed=0.0)
    return Scene(ego, {"stopped": stopped}, [],
                 lambda r: _require(max(r.speeds("stopped")) < 0.5, "the stopped car moved"))


def _stock_traffic_ego_lane_change(env, k: int) -> Scene:
    """highway-v0's own traffic (kept as reset made it, seed = variant); the stock ego is swapped for a green
    IDMVehicle at its place, which changes lanes to the left at 2 s."""
    road = env.road
    stock = env.vehicle
    others = [v for v in road.vehicles if v is not stock]
    road.vehicles.remove(stock)
    lane = stock.lane_index
    ego = _car(road, lane, stock.lane.local_coordinates(stock.position)[0], 25.0, ego=True)
    actors = {f"traffic{i}": v for i, v in enumerate(others)}

    def check(r: Record) -> Optional[str]:
        import math

        if _lane_ids(r, "ego")[-1] != lane[2] - 1:
            return "the ego did not change lanes to the left"
        for name in actors:
            d = min(math.hypot(s[name]["x"] - s["ego"]["x"], s[name]["y"] - s["ego"]["y"]) for s in r.steps)
            if d > 40.0:
                return f"{name} never came within 40 m of the ego"
        return None

    return Scene(ego, actors, [(2.0 + 0.4 * k, _set(ego, target_lane_index=(lane[0], lane[1], lane[2] - 1)))],
                 check)


def _rb_several(env, k: int) -> Scene:
    """roundabout-v0 with two other vehicles: two circle in the ring past the ego's entry (the ego enters
    behind them); the ego drives through to the north exit."""
    from highway_env.vehicle.behavior import IDMVehicle, LinearVehicle

    road = env.road
    ego = _car(road, ("ser", "ses", 0), 115.0 + 2 * k, 8.0, destination="nxr", ego=True)
    first = _vehicle(LinearVehicle, road, ("we", "sx", 0), 8.0 + 2 * k, 8.0, destination="exr")
    second = _vehicle(IDMVehicle, road, ("sx", "se", 0), 2.0 + 2 * k, 8.0, destination="exr")
    return Scene(ego, {"first": first, "second": second}, [],
                 lambda r: _require(_exits_north(r) and any(l[0] in ("se", "ex") for l in r.lanes("first")),
                                    "the ego did not drive through or the first car left early"))


SCRIPTS: List[Script] = []


def _script(name, env_id, use_case, description, elements, scene, seconds=10.0, **render) -> None:
    SCRIPTS.append(Script(name, env_id, use_case, description, elements, scene, seconds, **render))


def _el(road: str, participants: Sequence[str], actions: Sequence[Sequence[str]] = (),
        relations: Sequence[Sequence[str]] = ()) -> Dict[str, Any]:
    return {"road": road, "participants": list(participants), "actions": [list(a) for a in actions],
            "relations": [list(r) for r in relations]}


# ----------------------------------------------------------------------------- the scripts and their labels
# Each label below was written by hand from what the scene builder scripts.
_script("hw_lead_brakes", "highway-v0", "lead_vehicle_brakes",
        "On a multi-lane highway the car driving ahead of the ego in its lane brakes hard; another car drives "
        "in the lane to the right of the ego.",
        _el("highway", ["ego", "car", "car"], [["car", "brake"]],
            [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]),
        _hw_lead_brakes)
_script("hw_lead_stopped", "highway-v0", "lead_vehicle_stopped",
        "On a multi-lane highway a car stands still in the ego's lane ahead of it.",
        _el("highway", ["ego", "car"], [["car", "stop"]], [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]),
        _hw_lead_stopped)
_script("hw_cut_in_from_left", "highway-v0", "cut_in",
        "On a multi-lane highway a faster car in the lane to the left of the ego, slightly ahead of it, changes "
        "lanes to the right and cuts in just in front of the ego.",
        _el("highway", ["ego", "car"], [["car", "cut_in"], ["car", "lane_change_right"]],
            [["car", "ahead_of", "ego"], ["car", "left_of", "ego"]]),
        _hw_cut_in(-1))
_script("hw_cut_in_from_right", "highway-v0", "cut_in",
        "On a multi-lane highway a faster car in the lane to the right of the ego, slightly ahead of it, changes "
        "lanes to the left and cuts in just in front of the ego.",
        _el("highway", ["ego", "car"], [["car", "cut_in"], ["car", "lane_change_left"]],
            [["car", "ahead_of", "ego"], ["car", "right_of", "ego"]]),
        _hw_cut_in(+1))
_script("hw_overtaken_on_the_left", "highway-v0", "overtake",
        "On a multi-lane highway a much faster car comes from behind in the lane to the left of the ego and "
        "overtakes it without changing lanes.",
        _el("highway", ["ego", "car"], [["car", "overtake"]], [["car", "behind", "ego"], ["car", "left_of", "ego"]]),
        _hw_overtaken)
_script("hw_ego_passes_slow_car", "highway-v0", "ego_lane_change",
        "On a multi-lane highway the ego comes up behind a slower car in its lane, changes lanes to the left and "
        "overtakes it.",
        _el("highway", ["ego", "car"], [["ego", "lane_change_left"], ["ego", "overtake"]],
            [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]),
        _hw_ego_passes_slow_car)
_script("hw_obstacle_in_lane", "highway-v0", "obstacle_in_lane",
        "On a multi-lane highway an obstacle lies in the ego's lane ahead; the ego changes lanes to the left "
        "to pass it.",
        _el("highway", ["ego", "obstacle"], [["ego", "lane_change_left"]],
            [["obstacle", "ahead_of", "ego"], ["obstacle", "same_lane", "ego"]]),
        _hw_obstacle)
_script("merge_ramp_car_cuts_in", "merge-v0", "on_ramp_merge",
        "The ego drives in the right lane of a highway where an on-ramp joins; a car from the on-ramp, ahead "
        "of the ego, merges into the ego's lane in front of it.",
        _el("merge", ["ego", "car"], [["car", "cut_in"], ["car", "merge"]],
            [["car", "ahead_of", "ego"], ["car", "right_of", "ego"]]),
        _merge_from_ramp(1), seconds=10.0)
_script("merge_ramp_car_next_lane", "merge-v0", "on_ramp_merge",
        "The ego drives in the left lane of a highway where an on-ramp joins; a car from the on-ramp, ahead "
        "of the ego, merges into the right lane beside the ego's.",
        _el("merge", ["ego", "car"], [["car", "merge"]], [["car", "ahead_of", "ego"], ["car", "right_of", "ego"]]),
        _merge_from_ramp(0), seconds=10.0)
_script("ix_left_turn_oncoming", "intersection-v0", "left_turn_oncoming",
        "At a four-way intersection the ego turns left while an oncoming car goes straight through the "
        "intersection across the ego's path.",
        _el("intersection", ["ego", "car"], [["ego", "turn_left"], ["car", "go_straight"]],
            [["car", "oncoming", "ego"], ["car", "crossing_path", "ego"]]),
        _ix_left_turn_oncoming)
_script("ix_straight_crossing", "intersection-v0", "crossing_paths",
        "At a four-way intersection the ego goes straight while a car from the cross street drives straight "
        "through the intersection across the ego's path.",
        _el("intersection", ["ego", "car"], [["ego", "go_straight"], ["car", "go_straight"]],
            [["car", "crossing_path", "ego"]]),
        _ix_crossing)
_script("ix_right_turn_into_path", "intersection-v0", "turn_into_path",
        "At a four-way intersection a car from the street on the ego's right turns right into the ego's "
        "direction ahead of it while the ego goes straight.",
        _el("intersection", ["ego", "car"], [["ego", "go_straight"], ["car", "turn_right"]],
            [["car", "ahead_of", "ego"], ["car", "right_of", "ego"]]),
        _ix_right_turn_into_path)
_script("ix_oncoming_turns_left", "intersection-v0", "left_turn_oncoming",
        "At a four-way intersection an oncoming car turns left across the ego's path while the ego goes "
        "straight.",
        _el("intersection", ["ego", "car"], [["ego", "go_straight"], ["car", "turn_left"]],
            [["car", "oncoming", "ego"], ["car", "crossing_path", "ego"]]),
        _ix_oncoming_left_turn)
_script("ix_ego_turns_right", "intersection-v0", "ego_turn",
        "At an empty four-way intersection the ego turns right.",
        _el("intersection", ["ego"], [["ego", "turn_right"]]),
        _ix_ego_right_turn)
_script("rb_car_circling_ahead", "roundabout-v0", "roundabout",
        "At a roundabout a car already in the ring passes in front of the ego's entry; the ego enters behind it "
        "and drives straight through to the opposite exit.",
        _el("roundabout", ["ego", "car"], [["ego", "go_straight"]],
            [["car", "ahead_of", "ego"], ["car", "crossing_path", "ego"]]),
        _rb_enters_ahead, seconds=16.0)
_script("rb_car_enters_ahead", "roundabout-v0", "roundabout",
        "The ego drives straight through a roundabout; a car from the next entry merges into the ring in front "
        "of it.",
        _el("roundabout", ["ego", "car"], [["ego", "go_straight"], ["car", "merge"]], [["car", "ahead_of", "ego"]]),
        _rb_car_enters, seconds=16.0)
_script("rb_ego_first_exit", "roundabout-v0", "ego_turn",
        "The ego enters a roundabout behind another car and both take the first exit, turning right.",
        _el("roundabout", ["ego", "car"], [["ego", "turn_right"], ["car", "turn_right"]],
            [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]),
        _rb_first_exit, seconds=14.0)


# Stock vehicle classes drawn in highway-env's own colours (no colour set: LinearVehicle and its
# Aggressive/Defensive subclasses yellow, IDMVehicle blue, MDPVehicle green), a long vehicle, other
# scalings and screen sizes, a roundabout with several vehicles, stock traffic. Labels by hand, as above.
_script("cls_linear_cut_in", "highway-v0", "cut_in",
        "On a multi-lane highway a faster car in the lane to the left of the ego, slightly ahead of it, changes "
        "lanes to the right and cuts in just in front of the ego; another car drives far ahead on the right.",
        _el("highway", ["ego", "car", "car"], [["car", "cut_in"], ["car", "lane_change_right"]],
            [["car", "ahead_of", "ego"], ["car", "left_of", "ego"]]),
        _cls_linear_cut_in, scaling=3.5, size=(640, 320))
_script("cls_truck_lead_brakes", "highway-v0", "lead_vehicle_brakes",
        "On a multi-lane highway the truck driving ahead of the ego in its lane brakes hard; a car drives in "
        "the lane to the right of the ego.",
        _el("highway", ["ego", "truck", "car"], [["truck", "brake"]],
            [["truck", "ahead_of", "ego"], ["truck", "same_lane", "ego"]]),
        _cls_truck_lead_brakes, scaling=8.0, size=(800, 480))
_script("cls_lead_stopped_yellow", "highway-v0", "lead_vehicle_stopped",
        "On a multi-lane highway a car stands still in the ego's lane ahead of it; the ego stops behind it.",
        _el("highway", ["ego", "car"], [["car", "stop"]], [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]),
        _cls_lead_stopped_yellow, scaling=4.5, size=(600, 400))
_script("stock_traffic_ego_lane_change", "highway-v0", "ego_lane_change",
        "On a multi-lane highway with two other cars of the stock traffic driving ahead, the ego changes lanes "
        "to the left.",
        _el("highway", ["ego", "car", "car"], [["ego", "lane_change_left"]]),
        _stock_traffic_ego_lane_change, scaling=4.0, size=(720, 360), stock_traffic=2)
_script("rb_two_cars_pass_entry", "roundabout-v0", "roundabout",
        "At a roundabout two cars in the ring pass in front of the ego's entry; the ego enters behind them "
        "and drives straight through to the opposite exit.",
        _el("roundabout", ["ego", "car", "car"], [["ego", "go_straight"]],
            [["car", "ahead_of", "ego"], ["car", "crossing_path", "ego"]]),
        _rb_several, seconds=16.0, scaling=4.5, size=(600, 600))


# ----------------------------------------------------------------------------- rendering
def _env_config(script: "Script") -> Dict[str, Any]:
    seconds = script.seconds
    return {
        "offscreen_rendering": True, "screen_width": script.size[0], "screen_height": script.size[1],
        "scaling": script.scaling,
        "centering_position": [0.5, 0.5], "policy_frequency": FPS, "simulation_frequency": 15,
        "duration": seconds + 5, "show_trajectories": False, "render_agent": True,
        "vehicles_count": script.stock_traffic, "spawn_probability": 0.0, "offroad_terminal": False,
    }


def _state(vehicle) -> Dict[str, Any]:
    return {"lane": tuple(vehicle.lane_index), "x": float(vehicle.position[0]), "y": float(vehicle.position[1]),
            "speed": float(vehicle.speed), "heading": float(vehicle.heading), "crashed": bool(vehicle.crashed)}


def render_script(script: Script, variant: int, path: Optional[str | os.PathLike] = None) -> Dict[str, Any]:
    """Play ``script`` (variant ``variant``) in its stock env; write the clip to ``path`` when given.

    Returns ``{"frames", "record", "problem"}``; ``problem`` says what did not happen as scripted (None if all did).
    """
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the stock envs)
    import numpy as np

    from envs.recording import VideoWriter

    wrapped = gym.make(script.env_id, render_mode="rgb_array", config=_env_config(script))
    env = wrapped.unwrapped
    try:
        env.reset(seed=variant)
        if not script.stock_traffic:
            env.road.vehicles = []
        env.road.objects = []
        scene = script.scene(env, variant)
        env.vehicle = scene.ego
        env.action_type.controlled_vehicle = scene.ego
        named = {"ego": scene.ego, **scene.actors}
        pending = list(scene.events)
        steps = [{n: _state(v) for n, v in named.items()}]
        n_steps = int(round(script.seconds * FPS))
        writer = VideoWriter(path, fps=FPS) if path else None
        frames = 0
        try:
            if writer:
                writer.write(env.render())
            frames += 1
            idle = 1  # the action is ignored: every vehicle, the ego too, is an IDMVehicle
            for i in range(n_steps):
                t = i / FPS
                for event in [e for e in pending if (e[0]() if callable(e[0]) else e[0] <= t + 1e-9)]:
                    pending.remove(event)
                    event[1]()
                env.step(idle)
                steps.append({n: _state(v) for n, v in named.items()})
                if writer:
                    writer.write(env.render())
                frames += 1
                if any(v.crashed for v in env.road.vehicles):
                    break
        finally:
            if writer:
                writer.close()
        record = Record(steps)
        crashed = sorted(n for n, s in steps[-1].items() if s["crashed"])
        problem = scene.check(record)
        if crashed and not scene.crash_expected:
            problem = f"unscripted crash of {', '.join(crashed)}"
        ego_x = np.array([[s["ego"]["x"], s["ego"]["y"]] for s in steps])
        return {"frames": frames, "record": record, "problem": problem,
                "ego_path_m": float(np.sum(np.linalg.norm(np.diff(ego_x, axis=0), axis=1)))}
    finally:
        wrapped.close()


def build(out: str | os.PathLike, only: Optional[Sequence[str]] = None) -> List[Dict[str, Any]]:
    """Render every script's variants into ``out`` with their labels; returns one row per clip.

    Raises RuntimeError naming the clip when a scripted event did not happen.
    """
    from scenario_bank.elements import Elements

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for script in SCRIPTS:
        if only and script.name not in only:
            continue
        for k in VARIANTS:
            stem = f"{script.name}_v{k}"
            result = render_script(script, k, out / f"{stem}.webm")
            if result["problem"]:
                raise RuntimeError(f"{stem}: {result['problem']}; fix the script in make_external_evalset.py")
            label = {"use_case": script.use_case, "script": script.name, "variant": k, "env": script.env_id,
                     "seconds": script.seconds, "source": "stock highway-env, scripted and labelled by hand",
                     "description": script.description, "elements": Elements.from_dict(script.elements).to_dict()}
            if (script.scaling, tuple(script.size), script.stock_traffic) != (SCALING, (SIZE, SIZE), 0):
                label["render"] = {"scaling": script.scaling, "screen": list(script.size),
                                   "stock_traffic": script.stock_traffic}
            (out / f"{stem}.label.json").write_text(json.dumps(label, indent=1, sort_keys=True) + "\n",
                                                   encoding="utf-8")
            rows.append({"stem": stem, "frames": result["frames"]})
    return rows


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="output folder")
    parser.add_argument("--only", action="append", help="script name (repeatable; default: all)")
    args = parser.parse_args(argv)
    for row in build(args.out, args.only):
        print(f"{row['stem']}: {row['frames']} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
