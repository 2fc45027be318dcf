"""The maps the rule-based Scenario Generator composes on, by road type, and the dimensions it places with."""

from __future__ import annotations

import math
from typing import List, Tuple

from scenario_bank.elements import Road
from scenario_bank.maps.dimensions import LANE_WIDTH, ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS

__all__ = ["ROAD_MAPS", "MAP_ROADS", "JUNCTION_MAPS", "HIGHWAY_MAPS", "MULTILANE_STREET", "STREET_LANES", "RING_MAP",
           "PARKING_STREET", "STREET_MAPS", "SHOULDER_HIGHWAY", "SHOULDER_KERB", "PARKING_KERB", "PARKING_FAR_KERB",
           "RING_ENTRY", "RING_QUARTER", "at_kerb", "speed_ranges"]

ROAD_MAPS = {
    Road.HIGHWAY: "highway_straight",
    Road.MERGE: "highway_onramp",
    Road.STRAIGHT_ROAD: "urban_two_way",
    Road.INTERSECTION: "urban_crossroads",
    Road.T_JUNCTION: "urban_t_junction",
    Road.THREE_WAY: "urban_t_junction",
    Road.ROUNDABOUT: "urban_roundabout",
}
MAP_ROADS = {"highway_straight": "highway", "highway_onramp": "merge", "urban_two_way": "straight_road",
             "urban_parking": "straight_road",
             "urban_multilane": "straight_road", "urban_crossroads": "intersection", "urban_t_junction": "t_junction",
             "urban_roundabout": "roundabout"}
JUNCTION_MAPS = ("urban_crossroads", "urban_t_junction", "urban_roundabout")
HIGHWAY_MAPS = ("highway_straight", "highway_onramp")
MULTILANE_STREET = "urban_multilane"
"""The town street with two lanes per direction (and oncoming traffic), for streets that need a lane beside the
ego's; ``urban_two_way`` (one lane per direction) is the plain town street."""
STREET_LANES = 2
"""Lanes per direction of :data:`MULTILANE_STREET`."""
RING_MAP = "urban_roundabout"
PARKING_STREET = "urban_parking"
"""``urban_two_way`` with a parking lane at each kerb: the street of vehicles parked at the kerb, pulling out
of a parking space or backing out of one."""
STREET_MAPS = ("urban_two_way", PARKING_STREET)
"""The town streets with one lane per direction."""
SHOULDER_HIGHWAY = "highway_straight"
"""The highway with a hard shoulder (3 m, right of the rightmost lane): the ego parked on it pulls out from it."""
SHOULDER_KERB = "Range(2.15, 2.35)"
"""``right of <rightmost lane centre point> by`` this puts a car on the centre of :data:`SHOULDER_HIGHWAY`'s
hard shoulder (3.25 m right of the lane centre)."""
PARKING_KERB = "Range(1.9, 2.1)"
"""``right of <lane centre point> by`` this puts a car on the centre of the kerbside parking lane of
:data:`PARKING_STREET` (the car's left side ``LANE_WIDTH / 2 + 0.25`` m from the lane centre, give or take)."""
PARKING_FAR_KERB = "Range(5.4, 5.6)"
"""``left of <ego's lane centre point> by`` this puts a car on the far (oncoming side's) parking lane."""


def at_kerb(var: str, cls: str, along: str, kerb: str, behavior: str) -> List[str]:
    """Scenic lines for ``var``, a standing ``cls`` at the right kerb of the ego's lane: ``along`` metres down
    the lane's centre line, its left side ``kerb`` metres right of it (off the driving lane, so the lane
    containment requirement is lifted), facing the lane's direction."""
    return [f"{var}Spot = new OrientedPoint at egoLane.centerline.pointAlongBy({along}), facing roadDirection",
            f"{var} = new {cls} right of {var}Spot by {kerb}, facing {var}Spot.heading,",
            "    with regionContainedIn everywhere,",
            "    with speed 0,",
            f"    with behavior {behavior}"]


def _ring_lengths() -> Tuple[float, float]:
    """On :data:`RING_MAP`, the length along the lane centre of an entry curve (arm end to where it joins the
    ring) and of a quarter of the ring: a vehicle entering from the arm left of the ego's passes the ego's entry
    after both."""
    d, r, half = ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS, LANE_WIDTH / 2
    entry_radius = (d * d - r * r) / (2 * r)
    entry_turn = math.pi / 2 - math.atan2(entry_radius, d)
    return (entry_radius - half) * entry_turn, (r + half) * math.pi / 2


RING_ENTRY, RING_QUARTER = _ring_lengths()


def speed_ranges(map_name: str) -> Tuple[float, float]:
    return {"highway_straight": (20, 26), "highway_onramp": (18, 23), "urban_two_way": (8, 12), PARKING_STREET: (8, 12),
            MULTILANE_STREET: (8, 12)}.get(map_name, (6, 9))
