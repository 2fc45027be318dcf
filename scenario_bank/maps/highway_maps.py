"""The two motorway maps: ``highway_straight`` and ``highway_onramp`` (see
:mod:`scenario_bank.maps.build_maps` for their layout)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

from scenario_bank.maps.dimensions import LANE_WIDTH
from scenario_bank.maps.opendrive_model import (
    Pose,
    Line,
    Arc,
    NO_MARK,
    SOLID,
    Lane,
    LaneSection,
    Link,
    Road,
    Connection,
    Junction,
    OpenDriveMap,
    offset_point,
    assert_poses_meet,
)
from scenario_bank.maps.road_parts import (
    HIGHWAY_SPEED,
    taper_width,
    highway_right_lanes,
    highway_left_lanes,
    identity_links,
    LaneEnd,
    JunctionLink,
    connecting_road,
)

__all__ = [
    "build_highway_straight",
    "build_highway_onramp",
]


def build_highway_straight() -> OpenDriveMap:
    """One-way 4-lane motorway, 2000 m along +x."""
    road = Road(
        id=1,
        name="highway",
        start=(0.0, 0.0, 0.0),
        segments=(Line(2000.0),),
        sections=(
            LaneSection(
                s=0.0,
                left=highway_left_lanes(),
                right=highway_right_lanes(4),
                center_mark=SOLID,
            ),
        ),
        road_type="motorway",
        speed_kmh=HIGHWAY_SPEED,
    )
    return OpenDriveMap("highway_straight", [road])


_ONRAMP_JUNCTION = 10
_ONRAMP_MOTORWAY = dict(road_type="motorway", speed_kmh=HIGHWAY_SPEED)


@dataclass(frozen=True)
class _OnrampLengths:
    """The on-ramp map's lengths along +x (metres) and the ramp's approach angle (radians)."""

    before: float = 500.0
    junction: float = 80.0
    accel: float = 250.0
    taper: float = 80.0
    total: float = 1500.0
    ramp: float = 250.0
    ramp_angle: float = math.radians(6.0)

    @property
    def after(self) -> float:
        """What is left of the motorway after the taper."""
        return self.total - self.before - self.junction - self.accel - self.taper


def build_highway_onramp() -> OpenDriveMap:
    """One-way 3-lane motorway (1500 m) with an on-ramp and acceleration lane.

    Layout along +x (reference line on y = 0, driving lanes -1..-3 below it)::

        road 1 "before"  x    0 .. 500   3 lanes
        junction 10      x  500 .. 580   road 101 (3 lanes, straight) and
                                         road 102 (ramp lane, gentle right arc)
        road 2 "merge"   x  580 .. 910   section 0 (250 m): 3 lanes + accel lane -4
                                         section 1 (80 m): lane -4 tapers to 0 and ends
        road 3 "after"   x  910 .. 1500  3 lanes
        road 4 "ramp"    a 250 m straight approaching from the south-west at 6 deg
    """
    lengths = _OnrampLengths()
    before = Road(
        id=1,
        name="highway_before",
        start=(0.0, 0.0, 0.0),
        segments=(Line(lengths.before),),
        sections=(
            LaneSection(0.0, highway_left_lanes(), highway_right_lanes(3), SOLID),
        ),
        successor=Link("junction", _ONRAMP_JUNCTION),
        **_ONRAMP_MOTORWAY,
    )
    merge_start = (lengths.before + lengths.junction, 0.0, 0.0)
    main_link = connecting_road(
        101,
        "highway_through_junction",
        before.end_pose(),
        Line(lengths.junction),
        JunctionLink(_ONRAMP_JUNCTION, LaneEnd(1, "end", -1), LaneEnd(2, "start", -1), lanes=3),
        **_ONRAMP_MOTORWAY,
    )
    assert_poses_meet(main_link.end_pose(), merge_start, "junction 10 main line")
    ramp_link, ramp = _onramp_ramp(lengths, merge_start)
    merge = _onramp_merge_road(lengths, merge_start)
    after = _onramp_after_road(lengths, merge.end_pose())
    junction = Junction(
        _ONRAMP_JUNCTION,
        "onramp_merge",
        [
            Connection(1, 101, ((-1, -1), (-2, -2), (-3, -3))),
            Connection(4, 102, ((-1, -1),)),
        ],
    )
    return OpenDriveMap(
        "highway_onramp", [before, merge, after, ramp, main_link, ramp_link], [junction]
    )


def _onramp_ramp(lengths: _OnrampLengths, merge_start: Pose) -> Tuple[Road, Road]:
    """The ramp's connecting road through the junction (road 102) and the ramp itself (road 4).

    The accel lane (-4 of road 2) starts at y = -10.5 (its left edge). The ramp's connecting road ends
    there, heading +x, and its reference line (the ramp lane's left edge) is an arc that turns right by
    the ramp angle over the junction length; the ramp is a straight leading into that arc.
    """
    ramp_angle = lengths.ramp_angle
    accel_left_edge = offset_point(merge_start, -3 * LANE_WIDTH)
    radius = lengths.junction / math.sin(ramp_angle)
    ramp_conn_start = (
        accel_left_edge[0] - radius * math.sin(ramp_angle),
        accel_left_edge[1] - radius * (1.0 - math.cos(ramp_angle)),
        ramp_angle,
    )
    ramp_link = connecting_road(
        102,
        "ramp_into_acceleration_lane",
        ramp_conn_start,
        Arc(length=radius * ramp_angle, curvature=-1.0 / radius),
        JunctionLink(_ONRAMP_JUNCTION, LaneEnd(4, "end", -1), LaneEnd(2, "start", -4)),
        **_ONRAMP_MOTORWAY,
    )
    assert_poses_meet(
        ramp_link.end_pose(), (*accel_left_edge, 0.0), "junction 10 ramp into accel lane"
    )
    ramp_start = (
        ramp_conn_start[0] - lengths.ramp * math.cos(ramp_angle),
        ramp_conn_start[1] - lengths.ramp * math.sin(ramp_angle),
        ramp_angle,
    )
    ramp = Road(
        id=4,
        name="onramp",
        start=ramp_start,
        segments=(Line(lengths.ramp),),
        sections=(
            LaneSection(
                0.0,
                right=(
                    Lane(-1, "driving", LANE_WIDTH, SOLID),
                    Lane(-2, "shoulder", 1.5, NO_MARK),
                    Lane(-3, "border", 0.5, NO_MARK),
                ),
                center_mark=SOLID,
            ),
        ),
        successor=Link("junction", _ONRAMP_JUNCTION),
        **_ONRAMP_MOTORWAY,
    )
    assert_poses_meet(ramp.end_pose(), ramp_conn_start, "ramp end")
    return ramp_link, ramp


def _onramp_merge_road(lengths: _OnrampLengths, merge_start: Pose) -> Road:
    """Road 2: accel lane -4 alongside -3 (broken mark between them), then the taper.

    Lane -4 has no predecessor link in the road (it is reached through the junction) and no successor
    (it ends at the end of the taper).
    """
    merge_links_0 = identity_links([-1, -2, -3, -4, -5, -6], pred=False)
    merge_links_0.update(identity_links([1], pred=False))
    merge_sec0 = LaneSection(
        0.0,
        left=highway_left_lanes(merge_links_0),
        right=highway_right_lanes(4, links=merge_links_0),
        center_mark=SOLID,
    )
    # In the taper section the shoulder/border (-5/-6) continue as -4/-5 of road 3.
    taper_links = {
        -1: (-1, -1),
        -2: (-2, -2),
        -3: (-3, -3),
        -4: (-4, None),
        -5: (-5, -4),
        -6: (-6, -5),
        1: (1, 1),
    }
    taper_right = list(highway_right_lanes(4, links=taper_links))
    taper_right[3] = Lane(
        -4, "driving", taper_width(LANE_WIDTH, lengths.taper), SOLID, predecessor=-4
    )
    merge_sec1 = LaneSection(
        lengths.accel,
        left=highway_left_lanes(taper_links),
        right=tuple(taper_right),
        center_mark=SOLID,
    )
    return Road(
        id=2,
        name="highway_merge",
        start=merge_start,
        # two geometries so Scenic samples the short taper densely
        segments=(Line(lengths.accel), Line(lengths.taper)),
        sections=(merge_sec0, merge_sec1),
        predecessor=Link("junction", _ONRAMP_JUNCTION),
        successor=Link("road", 3, "start"),
        **_ONRAMP_MOTORWAY,
    )


def _onramp_after_road(lengths: _OnrampLengths, start: Pose) -> Road:
    """Road 3: the three lanes that continue after the taper (road 2's shoulder and border, -5/-6, become
    -4/-5 here)."""
    return Road(
        id=3,
        name="highway_after",
        start=start,
        segments=(Line(lengths.after),),
        sections=(
            LaneSection(
                0.0,
                left=highway_left_lanes(identity_links([1], succ=False)),
                # road 2's shoulder/border are -5/-6 (the accel lane was -4)
                right=highway_right_lanes(
                    3,
                    links={-1: (-1, None), -2: (-2, None), -3: (-3, None),
                           -4: (-5, None), -5: (-6, None)},
                ),
                center_mark=SOLID,
            ),
        ),
        predecessor=Link("road", 2, "end"),
        **_ONRAMP_MOTORWAY,
    )
