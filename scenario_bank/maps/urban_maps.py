"""The town maps: straight two-way streets (``urban_two_way``, ``urban_parking``, ``urban_multilane``) and the
junctions (``urban_crossroads``, ``urban_t_junction``, ``urban_roundabout``); see
:mod:`scenario_bank.maps.build_maps` for their layout."""

from __future__ import annotations

import math
from typing import Dict, List, Sequence, Tuple

from scenario_bank.maps.dimensions import LANE_WIDTH, ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS
from scenario_bank.maps.opendrive_model import (
    Pose,
    Line,
    Arc,
    RoadMark,
    NO_MARK,
    Lane,
    LaneSection,
    Link,
    Road,
    Connection,
    Junction,
    OpenDriveMap,
    wrap_angle,
    assert_poses_meet,
    turn_segment,
)
from scenario_bank.maps.road_parts import URBAN_SPEED, town_street_section, LaneEnd, JunctionLink, connecting_road

__all__ = [
    "straight_town_street",
    "build_urban_two_way",
    "build_urban_parking",
    "build_urban_multilane",
    "ARM_NAMES",
    "junction_arms",
    "build_intersection",
    "build_urban_crossroads",
    "build_urban_t_junction",
    "build_urban_roundabout",
]


def straight_town_street(name: str, section: LaneSection) -> OpenDriveMap:
    """A straight 600 m town street along +x, one road of lane section ``section``."""
    road = Road(
        id=1,
        name="street",
        start=(0.0, 0.0, 0.0),
        segments=(Line(600.0),),
        sections=(section,),
        road_type="town",
        speed_kmh=URBAN_SPEED,
    )
    return OpenDriveMap(name, [road])


def build_urban_two_way() -> OpenDriveMap:
    """Straight 600 m two-way street with sidewalks, along +x."""
    return straight_town_street("urban_two_way", town_street_section(RoadMark("broken", "yellow", "both")))


def build_urban_parking() -> OpenDriveMap:
    """Straight 600 m two-way street with a parking lane and a sidewalk on each side, along +x."""
    return straight_town_street("urban_parking",
                                town_street_section(RoadMark("broken", "yellow", "both"), parking=True))


def build_urban_multilane() -> OpenDriveMap:
    """Straight 600 m two-way town street, two lanes per direction, sidewalks, along +x."""
    return straight_town_street("urban_multilane",
                                town_street_section(RoadMark("solid solid", "yellow", "none", 0.3), 2))


ARM_NAMES = {0: "east", 90: "north", 180: "west", 270: "south"}


def junction_arms(arm_angles_deg: Sequence[int], start_distance: float, arm_length: float,
                  junction_id: int) -> Tuple[List[Road], Dict[int, Pose]]:
    """Straight two-way town arms (one lane each way, sidewalks) leaving a junction at the origin.

    Arm ``i`` (road id ``i + 1``) starts ``start_distance`` metres from the centre at
    ``arm_angles_deg[i]`` and runs outward, its predecessor the junction. Returns the
    roads and each road's start pose.
    """
    roads: List[Road] = []
    starts: Dict[int, Pose] = {}
    for index, angle_deg in enumerate(arm_angles_deg):
        if angle_deg % 90:
            raise ValueError("arms must be multiples of 90 degrees apart")
        road_id = index + 1
        hdg = math.radians(angle_deg)
        start = (start_distance * math.cos(hdg), start_distance * math.sin(hdg), hdg)
        starts[road_id] = start
        roads.append(
            Road(
                id=road_id,
                name=f"arm_{ARM_NAMES[angle_deg % 360]}",
                start=start,
                segments=(Line(arm_length),),
                sections=(town_street_section(RoadMark("solid", "yellow")),),
                predecessor=Link("junction", junction_id),
                road_type="town",
                speed_kmh=URBAN_SPEED,
            )
        )
    return roads, starts


def build_intersection(
    name: str,
    arm_angles_deg: Sequence[int],
    *,
    arm_length: float = 150.0,
    junction_half_size: float = 12.0,
    junction_id: int = 100,
) -> OpenDriveMap:
    """Two-way arms (one lane each way, sidewalks) meeting in one junction.

    Every arm starts ``junction_half_size`` metres from the centre (its
    predecessor is the junction) and runs outward, so lane 1 drives towards the
    junction and lane -1 away from it. For every ordered pair of distinct arms
    there is one connecting road from lane 1 of the first to lane -1 of the
    second. Its reference line (the left edge of its single lane) runs from the
    first arm's start to the second's: a line for straight movements, a
    quarter circle of radius ``junction_half_size`` for turns.
    """
    d = junction_half_size
    roads, starts = junction_arms(arm_angles_deg, d, arm_length, junction_id)
    arm_names = {road.id: road.name[len("arm_") :] for road in roads}

    junction = Junction(junction_id, f"{name}_junction")
    next_id = 101
    for from_id, from_start in starts.items():
        for to_id, to_start in starts.items():
            if from_id == to_id:
                continue
            entry = (from_start[0], from_start[1], wrap_angle(from_start[2] + math.pi))
            turn = wrap_angle(to_start[2] - entry[2])
            kind = {0: "straight", 90: "left", -90: "right"}[round(math.degrees(turn))]
            conn = connecting_road(
                next_id,
                f"{arm_names[from_id]}_to_{arm_names[to_id]}_{kind}",
                entry,
                turn_segment(turn, radius=d, straight_length=2 * d),
                JunctionLink(junction_id, LaneEnd(from_id, "start", 1), LaneEnd(to_id, "start", -1)),
                speed_kmh=URBAN_SPEED,
            )
            assert_poses_meet(conn.end_pose(), to_start, f"{name} {conn.name}")
            roads.append(conn)
            junction.connections.append(Connection(from_id, next_id, ((1, -1),)))
            next_id += 1
    return OpenDriveMap(name, roads, [junction])


def build_urban_crossroads() -> OpenDriveMap:
    """Four-way intersection, 150 m arms, 12 connecting roads."""
    return build_intersection("urban_crossroads", (0, 90, 180, 270))


def build_urban_t_junction() -> OpenDriveMap:
    """T-junction (east, west and south arms), 150 m arms, 6 connecting roads."""
    return build_intersection("urban_t_junction", (0, 180, 270))


def build_urban_roundabout(
    name: str = "urban_roundabout",
    *,
    ring_radius: float = ROUNDABOUT_RING_RADIUS,
    arm_start: float = ROUNDABOUT_ARM_START,
    arm_length: float = 150.0,
    junction_id: int = 100,
) -> OpenDriveMap:
    """Single-lane roundabout with four two-way arms (east, north, west, south), in one junction.

    The ring is driven counter-clockwise (right-hand traffic). Every movement from
    the inbound lane of one arm to the outbound lane of another (first, second and
    third exit: right, straight, left) is one connecting road whose reference line
    (the left edge of its single lane) is three arcs: a right-turning entry curve
    from the arm onto the ring, the ring itself (the reference line on the central
    island's edge, ``ring_radius``), and a right-turning exit curve onto the next
    arm. The entry curve is tangent to the arm and to the ring; its radius follows
    from ``arm_start`` and ``ring_radius`` (``(arm_start**2 - ring_radius**2) /
    (2 * ring_radius)``), and the exit curve is its mirror image. Connecting roads
    of different movements share the ring, as the lanes of a junction share its
    box, so Scenic sees every circulating path that meets the ego's as a
    conflicting maneuver.
    """
    d, r = arm_start, ring_radius
    entry_radius = (d * d - r * r) / (2.0 * r)
    # the entry curve meets the ring at this angle from the arm's axis
    meet = math.atan2(entry_radius, d)
    entry_turn = math.pi / 2 - meet  # right turn from the inbound heading onto the ring
    arm_angles = (0, 90, 180, 270)
    roads, starts = junction_arms(arm_angles, d, arm_length, junction_id)
    arm_names = {road.id: road.name[len("arm_") :] for road in roads}
    junction = Junction(junction_id, f"{name}_ring")
    next_id = 101
    exit_kind = {1: "first_exit_right", 2: "second_exit_straight", 3: "third_exit_left"}
    for from_id, from_start in starts.items():
        for steps in (1, 2, 3):
            to_id = (from_id - 1 + steps) % len(arm_angles) + 1
            to_start = starts[to_id]
            entry = (from_start[0], from_start[1], wrap_angle(from_start[2] + math.pi))
            ring_arc = math.pi / 2 * steps - 2 * meet
            segments = (
                Arc(length=entry_radius * entry_turn, curvature=-1.0 / entry_radius),
                Arc(length=r * ring_arc, curvature=1.0 / r),
                Arc(length=entry_radius * entry_turn, curvature=-1.0 / entry_radius),
            )
            conn = Road(
                id=next_id,
                name=f"{arm_names[from_id]}_to_{arm_names[to_id]}_{exit_kind[steps]}",
                start=entry,
                segments=segments,
                sections=(
                    LaneSection(
                        s=0.0,
                        right=(Lane(-1, "driving", LANE_WIDTH, NO_MARK, predecessor=1, successor=-1),),
                    ),
                ),
                predecessor=Link("road", from_id, "start"),
                successor=Link("road", to_id, "start"),
                junction=junction_id,
                road_type="town",
                speed_kmh=URBAN_SPEED,
            )
            assert_poses_meet(conn.end_pose(), to_start, f"{name} {conn.name}")
            roads.append(conn)
            junction.connections.append(Connection(from_id, next_id, ((1, -1),)))
            next_id += 1
    return OpenDriveMap(name, roads, [junction])
