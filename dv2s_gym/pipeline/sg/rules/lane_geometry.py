"""Section 3 of a straight-road script: the ego's lane and the lanes beside it that the actors need."""

from __future__ import annotations

from typing import Dict, List, Tuple

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.lane_roles import LaneRoad
from dv2s_gym.pipeline.sg.rules.roads import PARKING_STREET, STREET_LANES
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script

__all__ = ["LaneNames", "lane_geometry"]

_NAMES = {1: "leftLane", 2: "leftLane2", -1: "rightLane", -2: "rightLane2"}
_TUPLE_INDEX = {1: 1, 2: 2, -1: 3, -2: 4}


class LaneNames:
    """Scenic names of the lanes section 3 defines, by offset from the ego's lane (+ left, - right)."""

    def __init__(self, names: Dict[int, str]) -> None:
        self.names = names

    def __call__(self, k: int) -> str:
        """The lane at offset ``k``, else the nearest defined one on that side (the ego's lane at the last)."""
        if k in self.names:
            return self.names[k]
        nearest = max([x for x in self.names if (x > 0) == (k > 0) and abs(x) <= abs(k)], key=abs, default=0)
        return self.names[nearest]


def lane_geometry(s: Script, road: LaneRoad, need: Dict[int, bool]) -> LaneNames:
    """Write section 3 for the straight road; return the names of the lanes it defines."""
    if road.two_way:
        _street_geometry(s)
        return LaneNames({0: "egoLane"})
    conds, max_left, max_right = _lane_conditions(s, road, need)
    _lane_tuples(s, road, conds)
    lane_var = {0: "egoLane"}
    for k in sorted(need):
        if k in _NAMES and (k > 0 and k <= max_left or k < 0 and -k <= max_right):
            s.geometry.append(f"{_NAMES[k]} = laneTuple[{_TUPLE_INDEX[k]}]")
            lane_var[k] = _NAMES[k]
    if road.multilane and any(a.role == Role.ONCOMING for a in s.frame.actors):
        s.geometry.append("oncomingLane = laneTuple[7]")
    s.geometry.append("egoS = " + ("Range(5, 50)" if road.onramp else "Range(80, 330)" if road.multilane
                                   else "Range(150, 1200)"))
    if road.onramp:
        s.geometry += ["rampLane = Uniform(network.elements['road4_lane0'])",
                       "accelLane = network.elements['road2_lane0']"]
    return LaneNames(lane_var)


def _street_geometry(s: Script) -> None:
    s.geometry_title = ("a two-way urban street, one lane per direction, with a parking lane and a sidewalk "
                        "at each kerb" if s.frame.map == PARKING_STREET else
                        "a two-way urban street, one lane per direction, with sidewalks")
    s.geometry += ["lanePairs = [(lane, other) for lane in network.lanes for other in network.lanes "
                   "if other is not lane]",
                   "lanePair = Uniform(*lanePairs)",
                   "egoLane = lanePair[0]",
                   "oncomingLane = lanePair[1]",
                   "egoS = Range(80, 330)"]


def _lane_conditions(s: Script, road: LaneRoad, need: Dict[int, bool]) -> Tuple[List[str], int, int]:
    """Conditions on a lane tuple for the ego's lane, and how many lanes left and right of it are placed."""
    frame = s.frame
    total = 3 if road.onramp else STREET_LANES if road.multilane else 4
    max_left = max([k for k in need if k > 0], default=0)
    max_right = -min([k for k in need if k < 0], default=0)
    if max_left + max_right + 1 > total:
        s.warnings.append(f"the described lanes need {max_left + max_right + 1} lanes side by side; "
                          f"{frame.map} has {total}: some actors share a lane")
        max_left = min(max_left, total - 1)
        max_right = min(max_right, total - 1 - max_left)
    conds = []
    if max_left >= 1:
        conds.append("t[1] is not None")
    if max_left >= 2:
        conds.append("t[2] is not None")
    if max_right >= 1:
        conds.append("t[3] is not None")
    if max_right >= 2:
        conds.append("t[4] is not None")
    max_right = _at_kerb_conditions(s, road, conds, max_left, max_right)
    max_left = _oncoming_conditions(s, road, conds, max_left)
    if road.onramp and any(a.role == Role.RAMP for a in frame.actors):
        # the ego drives in the lane next to the acceleration lane the merger leaves
        conds[:] = [c for c in conds if not c.startswith("t[3]") and not c.startswith("t[4]")]
        conds.append("t[0] is mainLanes[0]")
        if max_right:
            s.warnings.append("lanes to the right of the ego cannot be placed next to an on-ramp merge")
            max_right = 0
    return conds, max_left, max_right


def _at_kerb_conditions(s: Script, road: LaneRoad, conds: List[str], max_left: int, max_right: int) -> int:
    """Conditions from where the ego is (parked at the kerb, in the lane the text names); the lanes right of
    it that can still be placed."""
    ego = s.frame.ego
    at_kerb = ego.has("pull_out") or ego.has("reverse") or any(a.role in (Role.PULLER, Role.SHOULDER)
                                                                for a in s.frame.actors)
    if at_kerb and not road.onramp:
        # a vehicle parked at the kerb or on the shoulder: the ego's lane is the rightmost one
        conds.append("t[3] is None")
        if max_right:
            s.warnings.append("lanes to the right of the ego cannot be placed next to a vehicle parked at "
                              "the kerb: they are not placed")
            max_right = 0
    if ego.lane == Lane.LEFT and max_left == 0:
        conds.append("t[1] is None")
    elif ego.lane == Lane.RIGHT and max_right == 0:
        # next to an on-ramp the acceleration lane is the right neighbour of the rightmost main lane
        conds.append("t[0] is mainLanes[0]" if road.onramp else "t[3] is None")
    elif ego.lane == Lane.MIDDLE:
        conds += ["t[1] is not None", "t[3] is not None"] if "t[1] is not None" not in conds or \
            "t[3] is not None" not in conds else []
    return max_right


def _oncoming_conditions(s: Script, road: LaneRoad, conds: List[str], max_left: int) -> int:
    if road.multilane and any(a.role == Role.ONCOMING and (a.has("drift") or a.has("collide"))
                              for a in s.frame.actors):
        # an oncoming vehicle that comes over the centre line meets the ego in the lane next to it
        conds[:] = [c for c in conds if not c.startswith("t[1]") and not c.startswith("t[2]")]
        conds.append("t[1] is None")
        if max_left:
            s.warnings.append("lanes to the left of the ego cannot be placed when an oncoming vehicle comes "
                              "over the centre line into the ego's lane: they are not placed")
            max_left = 0
    return max_left


def _lane_tuples(s: Script, road: LaneRoad, conds: List[str]) -> None:
    s.helpers.append("laneSides")
    source = ("[network.elements['road2_lane1'], network.elements['road2_lane2'], "
              "network.elements['road2_lane3']]" if road.onramp else "network.lanes")
    s.geometry_title = ("a three-lane highway with a one-lane on-ramp joining an acceleration lane" if road.onramp
                        else f"a straight two-way town street, {STREET_LANES} lanes per direction, with "
                             "sidewalks" if road.multilane else "a straight four-lane one-way highway")
    oncoming = road.multilane and any(a.role == Role.ONCOMING for a in s.frame.actors)
    if oncoming:
        # t[7]: the oncoming lane next to the centre line (left of the leftmost lane of the ego's direction)
        s.geometry += ["def oncomingOf(lane):",
                       "    inner = ([lane] + lanesLeftOf(lane))[-1].sections[0]._laneToLeft",
                       "    return None if inner is None else inner.lane",
                       ""]
    s.geometry += [f"mainLanes = {source}",
                   "laneTuples = [(lane, laneLeftOf(lane), laneLeftOf(laneLeftOf(lane)), laneRightOf(lane),",
                   "               laneRightOf(laneRightOf(lane)), len(lanesRightOf(lane)), "
                   "len(lanesLeftOf(lane))" + (", oncomingOf(lane)" if oncoming else "") +
                   ") for lane in mainLanes]",
                   "laneTuple = Uniform(*[t for t in laneTuples" + (f" if {' and '.join(dict.fromkeys(conds))}"
                                                                 if conds else "") + "])",
                   "egoLane = laneTuple[0]"]
