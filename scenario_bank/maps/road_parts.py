"""The parts the map builders share: speed limits, tapered widths, highway and town-street lane sections,
identity lane links and the connecting roads inside a junction."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Iterable, Optional, Tuple

from scenario_bank.maps.dimensions import LANE_WIDTH, PARKING_WIDTH, SIDEWALK_WIDTH
from scenario_bank.maps.opendrive_model import (
    Pose,
    WidthPoly,
    Segment,
    RoadMark,
    NO_MARK,
    SOLID,
    BROKEN,
    Lane,
    LaneSection,
    Link,
    Road,
)

__all__ = [
    "HIGHWAY_SPEED",
    "URBAN_SPEED",
    "taper_width",
    "highway_right_lanes",
    "highway_left_lanes",
    "identity_links",
    "town_street_section",
    "LaneEnd",
    "JunctionLink",
    "connecting_road",
]


HIGHWAY_SPEED = 120.0
URBAN_SPEED = 50.0


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
