"""Deterministic generator for the OpenDRIVE maps shipped in this folder.

Run ``python -m scenario_bank.maps.build_maps [--out DIR]`` to (re)write every
map as ``<name>.xodr``; the default output folder is the one this file lives in.
The output is byte-identical on every run: there are no timestamps, floats are
printed with a fixed format, and elements and attributes are always written in
the same order.

All maps use a local metric frame (x east, y north, metres; OpenDRIVE headings
in radians counter-clockwise from +x) and right-hand traffic: lanes with
negative ids (right of the reference line) drive along increasing ``s``.

The maps are written for Scenic's OpenDRIVE parser
(``scenic.formats.opendrive.xodr_parser``), so they stick to what it handles:

* the plan view uses only ``line`` and ``arc`` geometries;
* roads that meet a junction carry no lane links at that end; the junction's
  ``laneLink`` entries and the connecting roads' own lane links connect them;
* every connecting road starts at its incoming road (``contactPoint="start"``)
  and has a single right lane (-1), so Scenic turns it into one maneuver;
* junction ids are non-zero (Scenic treats a junction id of 0 as "no junction").

Maps:

``highway_straight``
    2000 m, one direction, 4 driving lanes (-1..-4) along +x, with a median
    strip on the left and a shoulder and border on the right.
``highway_onramp``
    1500 m, one direction, 3 driving lanes. Road 1 (before) and the ramp
    (road 4) meet in junction 10; both continue into road 2 (merge), whose first
    lane section has a 4th, acceleration lane (-4) for 250 m, which then tapers
    to zero width and ends. Road 3 (after) continues with 3 lanes.
``urban_two_way``
    600 m two-way road, one 3.5 m driving lane per direction and a 2 m sidewalk
    on each side.
``urban_parking``
    600 m two-way town street, one 3.5 m driving lane per direction, a 2.5 m
    parking lane (OpenDRIVE type ``parking``) at each kerb and a 2 m sidewalk
    beyond it.
``urban_multilane``
    600 m two-way town street, two 3.5 m driving lanes per direction (broken
    white line between same-direction lanes, solid double yellow centre line)
    and a 2 m sidewalk on each side.
``urban_crossroads``
    Four 150 m two-way arms with sidewalks meeting in junction 100, which holds
    12 connecting roads (left, straight and right from every incoming lane).
``urban_t_junction``
    Three 150 m two-way arms with sidewalks meeting in junction 100, which holds
    6 connecting roads (every movement except U-turns).
``urban_roundabout``
    Single-lane roundabout (ring lane 3.5 m wide around a 12 m central island,
    driven counter-clockwise) with four 150 m two-way arms with sidewalks, all
    in junction 100: 12 connecting roads, one per entry and exit (first, second
    and third exit), each an entry curve, part of the ring and an exit curve.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

from scenario_bank.maps.dimensions import (LANE_WIDTH, PARKING_WIDTH, ROUNDABOUT_ARM_START,  # noqa: F401 (re-exported)
                                           ROUNDABOUT_RING_RADIUS, SIDEWALK_WIDTH)

__all__ = [
    "LANE_WIDTH",
    "PARKING_WIDTH",
    "MAP_BUILDERS",
    "Line",
    "Arc",
    "RoadMark",
    "Lane",
    "LaneSection",
    "Link",
    "Road",
    "Connection",
    "Junction",
    "OpenDriveMap",
    "format_float",
    "map_to_xml",
    "write_maps",
    "main",
]

MARK_WIDTH = 0.15
DEFAULT_OUT_DIR = pathlib.Path(__file__).resolve().parent

Pose = Tuple[float, float, float]  # x, y, heading (rad, CCW from +x)
WidthPoly = Tuple[float, float, float, float]  # OpenDRIVE cubic a, b, c, d


# ---------------------------------------------------------------------------
# Number formatting
# ---------------------------------------------------------------------------


def format_float(value: float) -> str:
    """Format a number the same way on every run and platform.

    Twelve significant digits absorb last-bit differences between math
    libraries; values within 1e-9 of zero are written as ``0`` (no ``-0``).
    """
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"cannot write non-finite number {value!r} to OpenDRIVE")
    if abs(value) < 1e-9:
        return "0"
    text = f"{value:.12g}"
    return "0" if text in ("0", "-0") else text


# ---------------------------------------------------------------------------
# Data model
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Line:
    """A straight plan-view segment."""

    length: float


@dataclass(frozen=True)
class Arc:
    """A constant-curvature plan-view segment (curvature > 0 turns left)."""

    length: float
    curvature: float


Segment = Union[Line, Arc]


@dataclass(frozen=True)
class RoadMark:
    """Marking on a lane's outer border (the border away from the centre lane)."""

    type: str = "solid"  # solid, broken, solid solid, curb, none, ...
    color: str = "standard"  # standard (white), yellow, ...
    lane_change: str = "none"  # none, both, increase, decrease
    width: float = MARK_WIDTH


NO_MARK = RoadMark(type="none", lane_change="both", width=0.0)
SOLID = RoadMark(type="solid", lane_change="none")
BROKEN = RoadMark(type="broken", lane_change="both")


@dataclass(frozen=True)
class Lane:
    """One lane of a lane section.

    ``width`` is a constant in metres or an OpenDRIVE cubic ``(a, b, c, d)`` in
    the distance from the start of the lane section. ``predecessor`` and
    ``successor`` are lane ids in the neighbouring lane section or road.
    """

    id: int
    type: str = "driving"
    width: Union[float, WidthPoly] = LANE_WIDTH
    mark: RoadMark = NO_MARK
    predecessor: Optional[int] = None
    successor: Optional[int] = None


@dataclass(frozen=True)
class LaneSection:
    """Lanes from ``s`` to the next section (or the road's end)."""

    s: float
    left: Tuple[Lane, ...] = ()  # ids 1, 2, ... (inner to outer)
    right: Tuple[Lane, ...] = ()  # ids -1, -2, ... (inner to outer)
    center_mark: RoadMark = NO_MARK


@dataclass(frozen=True)
class Link:
    """A road's predecessor or successor: another road (with the contact point
    ``start``/``end`` on it) or a junction."""

    element_type: str  # "road" or "junction"
    element_id: int
    contact_point: Optional[str] = None  # only for roads


@dataclass
class Road:
    """An OpenDRIVE road: reference line from ``start`` plus lane sections."""

    id: int
    name: str
    start: Pose
    segments: Sequence[Segment]
    sections: Sequence[LaneSection]
    predecessor: Optional[Link] = None
    successor: Optional[Link] = None
    junction: int = -1
    road_type: str = "town"
    speed_kmh: Optional[float] = None

    @property
    def length(self) -> float:
        return sum(seg.length for seg in self.segments)

    def geometries(self) -> List[Tuple[float, Pose, Segment]]:
        """``(s, start pose, segment)`` of every plan-view segment."""
        out = []
        s = 0.0
        pose = self.start
        for seg in self.segments:
            out.append((s, pose, seg))
            pose = advance(pose, seg, seg.length)
            s += seg.length
        return out

    def end_pose(self) -> Pose:
        """Pose (x, y, heading) at the end of the reference line."""
        pose = self.start
        for seg in self.segments:
            pose = advance(pose, seg, seg.length)
        return pose


@dataclass(frozen=True)
class Connection:
    """A junction connection: ``incoming`` road enters ``connecting`` road at its
    ``contact`` end; ``lane_links`` maps incoming lane ids to connecting ones."""

    incoming: int
    connecting: int
    lane_links: Tuple[Tuple[int, int], ...]
    contact: str = "start"


@dataclass
class Junction:
    """A junction and its connections."""

    id: int
    name: str
    connections: List[Connection] = field(default_factory=list)


@dataclass
class OpenDriveMap:
    """A whole map: roads and junctions, written in list order."""

    name: str
    roads: List[Road]
    junctions: List[Junction] = field(default_factory=list)


# ---------------------------------------------------------------------------
# Geometry
# ---------------------------------------------------------------------------


def wrap_angle(angle: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def advance(pose: Pose, seg: Segment, ds: float) -> Pose:
    """Pose reached after driving ``ds`` metres along ``seg`` from ``pose``."""
    x, y, hdg = pose
    if isinstance(seg, Line) or seg.curvature == 0:
        return (x + ds * math.cos(hdg), y + ds * math.sin(hdg), hdg)
    k = seg.curvature
    new_hdg = hdg + k * ds
    return (
        x + (math.sin(new_hdg) - math.sin(hdg)) / k,
        y - (math.cos(new_hdg) - math.cos(hdg)) / k,
        new_hdg,
    )


def offset_point(pose: Pose, lateral: float) -> Tuple[float, float]:
    """Point ``lateral`` metres to the left (negative: right) of ``pose``."""
    x, y, hdg = pose
    return (x - lateral * math.sin(hdg), y + lateral * math.cos(hdg))


def assert_poses_meet(a: Pose, b: Pose, what: str, tol: float = 1e-6) -> None:
    """Fail loudly if two poses that should coincide do not (generator bug)."""
    if math.hypot(a[0] - b[0], a[1] - b[1]) > tol or abs(wrap_angle(a[2] - b[2])) > tol:
        raise AssertionError(f"{what}: poses {a} and {b} do not meet")


def turn_segment(turn: float, radius: float, straight_length: float) -> Segment:
    """Segment for a movement turning by ``turn`` radians (0 = straight)."""
    if abs(turn) < 1e-9:
        return Line(straight_length)
    return Arc(length=abs(turn) * radius, curvature=math.copysign(1.0 / radius, turn))


def _section_half_widths(section: LaneSection) -> Tuple[float, float]:
    def max_width(lane: Lane) -> float:
        if isinstance(lane.width, tuple):
            return abs(lane.width[0])  # our cubic widths only shrink from ``a``
        return lane.width

    return (
        sum(max_width(lane) for lane in section.left),
        sum(max_width(lane) for lane in section.right),
    )


def map_bounds(roads: Iterable[Road]) -> Tuple[float, float, float, float]:
    """Approximate (north, south, east, west) of all roads, lanes included."""
    xs: List[float] = []
    ys: List[float] = []
    for road in roads:
        pad = max(max(_section_half_widths(sec)) for sec in road.sections)
        for _, pose, seg in road.geometries():
            for i in range(17):
                px, py, _ = advance(pose, seg, seg.length * i / 16)
                xs.extend((px - pad, px + pad))
                ys.extend((py - pad, py + pad))
    return max(ys), min(ys), max(xs), min(xs)


# ---------------------------------------------------------------------------
# XML writing
# ---------------------------------------------------------------------------


def _sub(parent: ET.Element, tag: str, **attrs) -> ET.Element:
    """Append a child element; ``None`` attributes are left out, numbers formatted."""
    elem = ET.SubElement(parent, tag)
    for key, value in attrs.items():
        if value is None:
            continue
        key = key.rstrip("_")
        if isinstance(value, bool) or isinstance(value, str):
            elem.set(key, str(value).lower() if isinstance(value, bool) else value)
        elif isinstance(value, int):
            elem.set(key, str(value))
        else:
            elem.set(key, format_float(value))
    return elem


def _poly(parent: ET.Element, tag: str, s_key: str, s: float, coeffs: WidthPoly) -> None:
    a, b, c, d = coeffs
    _sub(parent, tag, **{s_key: float(s)}, a=float(a), b=float(b), c=float(c), d=float(d))


def _link_xml(parent: ET.Element, road: Road) -> None:
    if road.predecessor is None and road.successor is None:
        return
    link = _sub(parent, "link")
    for tag, target in (("predecessor", road.predecessor), ("successor", road.successor)):
        if target is None:
            continue
        _sub(
            link,
            tag,
            elementType=target.element_type,
            elementId=str(target.element_id),
            contactPoint=target.contact_point,
        )


def _plan_view_xml(parent: ET.Element, road: Road) -> None:
    plan_view = _sub(parent, "planView")
    for s, (x, y, hdg), seg in road.geometries():
        geom = _sub(plan_view, "geometry", s=s, x=x, y=y, hdg=hdg, length=seg.length)
        if isinstance(seg, Line):
            _sub(geom, "line")
        else:
            _sub(geom, "arc", curvature=seg.curvature)


def _road_mark_xml(parent: ET.Element, mark: RoadMark) -> None:
    _sub(
        parent,
        "roadMark",
        sOffset=0.0,
        type_=mark.type,
        weight="standard",
        color=mark.color,
        material="standard",
        width=mark.width,
        laneChange=mark.lane_change,
    )


def _lane_xml(parent: ET.Element, lane: Lane) -> None:
    elem = _sub(parent, "lane", id=str(lane.id), type_=lane.type, level=False)
    if lane.predecessor is not None or lane.successor is not None:
        link = _sub(elem, "link")
        if lane.predecessor is not None:
            _sub(link, "predecessor", id=str(lane.predecessor))
        if lane.successor is not None:
            _sub(link, "successor", id=str(lane.successor))
    width = lane.width if isinstance(lane.width, tuple) else (lane.width, 0.0, 0.0, 0.0)
    _poly(elem, "width", "sOffset", 0.0, width)
    _road_mark_xml(elem, lane.mark)


def _check_section(road: Road, section: LaneSection) -> None:
    left_ids = [lane.id for lane in section.left]
    right_ids = [lane.id for lane in section.right]
    if left_ids != list(range(1, len(left_ids) + 1)):
        raise AssertionError(f"road {road.id}: left lane ids must be 1..n, got {left_ids}")
    if right_ids != list(range(-1, -len(right_ids) - 1, -1)):
        raise AssertionError(f"road {road.id}: right lane ids must be -1..-n, got {right_ids}")


def _lanes_xml(parent: ET.Element, road: Road) -> None:
    lanes = _sub(parent, "lanes")
    _poly(lanes, "laneOffset", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    for section in road.sections:
        _check_section(road, section)
        sec = _sub(lanes, "laneSection", s=float(section.s))
        if section.left:
            left = _sub(sec, "left")
            for lane in reversed(section.left):  # outermost first, as in the spec
                _lane_xml(left, lane)
        center = _sub(sec, "center")
        center_lane = _sub(center, "lane", id="0", type_="none", level=False)
        _road_mark_xml(center_lane, section.center_mark)
        if section.right:
            right = _sub(sec, "right")
            for lane in section.right:
                _lane_xml(right, lane)


def road_to_xml(parent: ET.Element, road: Road) -> ET.Element:
    """Append the ``<road>`` element for ``road`` to ``parent``."""
    elem = _sub(
        parent,
        "road",
        name=road.name,
        length=road.length,
        id=str(road.id),
        junction=str(road.junction),
    )
    _link_xml(elem, road)
    road_type = _sub(elem, "type", s=0.0, type_=road.road_type)
    if road.speed_kmh is not None:
        _sub(road_type, "speed", max=road.speed_kmh, unit="km/h")
    _plan_view_xml(elem, road)
    elevation = _sub(elem, "elevationProfile")
    _poly(elevation, "elevation", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    lateral = _sub(elem, "lateralProfile")
    _poly(lateral, "superelevation", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    _lanes_xml(elem, road)
    return elem


def junction_to_xml(parent: ET.Element, junction: Junction) -> ET.Element:
    """Append the ``<junction>`` element for ``junction`` to ``parent``."""
    elem = _sub(parent, "junction", id=str(junction.id), name=junction.name)
    for index, conn in enumerate(junction.connections):
        c = _sub(
            elem,
            "connection",
            id=str(index),
            incomingRoad=str(conn.incoming),
            connectingRoad=str(conn.connecting),
            contactPoint=conn.contact,
        )
        for from_id, to_id in conn.lane_links:
            _sub(c, "laneLink", from_=str(from_id), to=str(to_id))
    return elem


def _check_map(odr: OpenDriveMap) -> None:
    road_ids = [road.id for road in odr.roads]
    if len(set(road_ids)) != len(road_ids):
        raise AssertionError(f"{odr.name}: duplicate road ids {road_ids}")
    roads = {road.id: road for road in odr.roads}
    for junction in odr.junctions:
        if junction.id == 0:
            raise AssertionError("junction id 0 is read as 'no junction' by Scenic")
        for conn in junction.connections:
            if roads[conn.connecting].junction != junction.id:
                raise AssertionError(
                    f"{odr.name}: road {conn.connecting} is not inside junction {junction.id}"
                )
            if conn.incoming not in roads:
                raise AssertionError(f"{odr.name}: unknown incoming road {conn.incoming}")


def map_to_xml(odr: OpenDriveMap) -> str:
    """Serialise a map to OpenDRIVE 1.4 XML text (deterministic)."""
    _check_map(odr)
    root = ET.Element("OpenDRIVE")
    north, south, east, west = map_bounds(odr.roads)
    _sub(
        root,
        "header",
        revMajor="1",
        revMinor="4",
        name=odr.name,
        version="1.0",
        north=north,
        south=south,
        east=east,
        west=west,
        vendor="dv2s-gym scenario_bank.maps.build_maps",
    )
    for road in odr.roads:
        road_to_xml(root, road)
    for junction in odr.junctions:
        junction_to_xml(root, junction)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode", short_empty_elements=True)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"


# ---------------------------------------------------------------------------
# Lane helpers
# ---------------------------------------------------------------------------


def taper_width(width: float, length: float) -> WidthPoly:
    """Cubic that shrinks smoothly from ``width`` to 0 over ``length`` metres
    (zero slope at both ends)."""
    return (width, 0.0, -3.0 * width / length**2, 2.0 * width / length**3)


def highway_right_lanes(
    n_driving: int,
    *,
    links: Optional[Dict[int, Tuple[Optional[int], Optional[int]]]] = None,
    last_mark: RoadMark = SOLID,
    shoulder_width: float = 3.0,
    border_width: float = 0.5,
) -> Tuple[Lane, ...]:
    """Right side of a one-way carriageway: driving lanes -1..-n (broken marks
    between them, ``last_mark`` on the outer edge), then a shoulder and a border.

    ``links`` maps a lane id to its ``(predecessor, successor)`` lane ids.
    """
    links = links or {}
    lanes = []
    for i in range(1, n_driving + 1):
        lane_id = -i
        pred, succ = links.get(lane_id, (None, None))
        mark = last_mark if i == n_driving else BROKEN
        lanes.append(Lane(lane_id, "driving", LANE_WIDTH, mark, pred, succ))
    for offset, (lane_type, width) in enumerate(
        (("shoulder", shoulder_width), ("border", border_width)), start=1
    ):
        lane_id = -(n_driving + offset)
        pred, succ = links.get(lane_id, (None, None))
        lanes.append(Lane(lane_id, lane_type, width, NO_MARK, pred, succ))
    return tuple(lanes)


def highway_left_lanes(
    links: Optional[Dict[int, Tuple[Optional[int], Optional[int]]]] = None,
) -> Tuple[Lane, ...]:
    """Left side of a one-way carriageway: a 2 m strip of central reservation.

    Its type is ``median`` rather than ``shoulder``: Scenic only models the
    shoulder on the right of a lane group, and a left-hand shoulder on a road
    without backward lanes would become a stray element outside
    ``network.shoulders``. Scenic ignores ``median`` lanes.
    """
    links = links or {}
    return (Lane(1, "median", 2.0, NO_MARK, *links.get(1, (None, None))),)


def identity_links(ids: Iterable[int], pred: bool = True, succ: bool = True):
    """``{id: (id or None, id or None)}`` for lanes that continue unchanged."""
    return {i: (i if pred else None, i if succ else None) for i in ids}


def town_street_section(center_mark: RoadMark, lanes_per_direction: int = 1, parking: bool = False) -> LaneSection:
    """``lanes_per_direction`` driving lanes each way (broken marks between same-direction lanes, solid on
    the kerb side), with ``parking`` a parking lane at each kerb, then a sidewalk on each side."""

    def side(sign: int) -> Tuple[Lane, ...]:
        lanes = [
            Lane(sign * i, "driving", LANE_WIDTH, SOLID if i == lanes_per_direction else BROKEN)
            for i in range(1, lanes_per_direction + 1)
        ]
        if parking:
            lanes.append(Lane(sign * (len(lanes) + 1), "parking", PARKING_WIDTH, NO_MARK))
        lanes.append(Lane(sign * (len(lanes) + 1), "sidewalk", SIDEWALK_WIDTH, NO_MARK))
        return tuple(lanes)

    return LaneSection(s=0.0, left=side(1), right=side(-1), center_mark=center_mark)


@dataclass(frozen=True)
class LaneEnd:
    """Lane ``lane`` of road ``road`` at its ``contact`` end (``"start"`` or ``"end"``)."""

    road: int
    contact: str
    lane: int


@dataclass(frozen=True)
class JunctionLink:
    """What a connecting road of junction ``junction`` joins: ``lanes`` lanes side by side from ``source`` on."""

    junction: int
    source: LaneEnd
    target: LaneEnd
    lanes: int = 1


def connecting_road(
    road_id: int,
    name: str,
    start: Pose,
    segment: Segment,
    link: JunctionLink,
    *,
    road_type: str = "town",
    speed_kmh: Optional[float] = None,
) -> Road:
    """Road inside junction ``link.junction`` whose right lanes -1..-``link.lanes`` link lane
    ``from_lane - k`` of the source road to lane ``to_lane - k`` of the target road
    (k = 0, 1, ...; lane ids count outward so this keeps lanes side by side)."""
    from_lane, to_lane = link.source.lane, link.target.lane
    right = []
    for k in range(link.lanes):
        sign_from = -1 if from_lane < 0 else 1
        sign_to = -1 if to_lane < 0 else 1
        right.append(
            Lane(
                -(k + 1),
                "driving",
                LANE_WIDTH,
                NO_MARK,
                predecessor=from_lane + sign_from * k,
                successor=to_lane + sign_to * k,
            )
        )
    return Road(
        id=road_id,
        name=name,
        start=start,
        segments=(segment,),
        sections=(LaneSection(s=0.0, right=tuple(right)),),
        predecessor=Link("road", link.source.road, link.source.contact),
        successor=Link("road", link.target.road, link.target.contact),
        junction=link.junction,
        road_type=road_type,
        speed_kmh=speed_kmh,
    )


# ---------------------------------------------------------------------------
# Maps
# ---------------------------------------------------------------------------


HIGHWAY_SPEED = 120.0
URBAN_SPEED = 50.0


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


MAP_BUILDERS: Dict[str, Callable[[], OpenDriveMap]] = {
    "highway_straight": build_highway_straight,
    "highway_onramp": build_highway_onramp,
    "urban_two_way": build_urban_two_way,
    "urban_parking": build_urban_parking,
    "urban_multilane": build_urban_multilane,
    "urban_crossroads": build_urban_crossroads,
    "urban_t_junction": build_urban_t_junction,
    "urban_roundabout": build_urban_roundabout,
}
"""Map name -> builder, in the order the maps are written."""


# ---------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------


def write_maps(out_dir: Union[str, pathlib.Path] = DEFAULT_OUT_DIR) -> List[pathlib.Path]:
    """Write every map to ``out_dir/<name>.xodr`` and return the paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, builder in MAP_BUILDERS.items():
        odr = builder()
        assert odr.name == name, (odr.name, name)
        path = out / f"{name}.xodr"
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(map_to_xml(odr))
        paths.append(path)
    return paths


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(
        prog="python -m scenario_bank.maps.build_maps",
        description="Write the shipped OpenDRIVE maps (deterministic output).",
    )
    parser.add_argument(
        "--out",
        type=pathlib.Path,
        default=DEFAULT_OUT_DIR,
        help=f"output folder (default: {DEFAULT_OUT_DIR})",
    )
    args = parser.parse_args(argv)
    for path in write_maps(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
