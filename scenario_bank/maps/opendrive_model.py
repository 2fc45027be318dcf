"""The OpenDRIVE map model the map builder writes: numbers in a fixed format, plan-view segments (lines and
arcs), road marks, lanes, lane sections, links, roads, junctions and whole maps, and the plan-view geometry
(poses along a segment, offsets, bounds) the builders lay roads out with."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, List, Optional, Sequence, Tuple, Union

from scenario_bank.maps.dimensions import LANE_WIDTH

__all__ = [
    "MARK_WIDTH",
    "Pose",
    "WidthPoly",
    "format_float",
    "Line",
    "Arc",
    "Segment",
    "RoadMark",
    "NO_MARK",
    "SOLID",
    "BROKEN",
    "Lane",
    "LaneSection",
    "Link",
    "Road",
    "Connection",
    "Junction",
    "OpenDriveMap",
    "wrap_angle",
    "advance",
    "offset_point",
    "assert_poses_meet",
    "turn_segment",
    "map_bounds",
]


MARK_WIDTH = 0.15

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
