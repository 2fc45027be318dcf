"""Scenic road network to highway-env: :func:`convert_network` builds the graph (an edge per Scenic lane group,
nodes glued by lane links) and :class:`ConvertedNetwork` holds the two networks side by side, with the look-ups
between them (lane indexes, successors, routes, shoulders)."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import (
    TYPE_CHECKING,
    Any,
    Dict,
    FrozenSet,
    Iterable,
    List,
    Optional,
    Sequence,
    Tuple,
    Union,
)

import numpy as np
import shapely
from highway_env.road.lane import (
    AbstractLane,
    LineType,
    StraightLane,
)
from highway_env.road.road import RoadNetwork

from envs.coordinates import (
    hw_to_scenic_position,
    scenic_to_hw_heading,
)
from envs.road_network.lanes import IndexedRoadNetwork, LaneIndex, Polyline, PolylineLane, dedupe_vertices

if TYPE_CHECKING:  # pragma: no cover - typing only
    from scenic.domains.driving.roads import Lane, Network

__all__ = [
    "STRAIGHT_TOLERANCE",
    "WIDTH_TOLERANCE",
    "LINK_TOLERANCE",
    "DEFAULT_SPEED_LIMIT",
    "ConvertedNetwork",
    "scenic_successors",
    "convert_network",
]

logger = logging.getLogger(__name__)

STRAIGHT_TOLERANCE = 0.05
"""Max distance [m] of a centerline vertex from its chord for a ``StraightLane``."""

WIDTH_TOLERANCE = 0.25
"""Max width variation [m] along a lane for a constant-width ``StraightLane``."""

LINK_TOLERANCE = 2.0
"""Max gap [m] between a lane's end and its successor's start to join their nodes."""

DEFAULT_SPEED_LIMIT = 20.0
"""Speed limit [m/s] used when neither Scenic nor the map file gives one (highway-env's default)."""

_MIN_LENGTH = 1e-3


# ---------------------------------------------------------------------------
# Conversion
# ---------------------------------------------------------------------------


@dataclass(eq=False)
class ConvertedNetwork:
    """A Scenic road network together with its highway-env conversion.

    Treat it as read-only: :func:`load_road_network` hands the same object to
    every caller of the same map.
    """

    #: The highway-env road network (an :class:`IndexedRoadNetwork`).
    hw_network: RoadNetwork
    #: The Scenic network it was converted from.
    scenic_network: "Network"
    #: Scenic lane uid -> highway-env lane index.
    lane_index_of: Dict[str, LaneIndex]
    #: highway-env lane index -> Scenic lane uid (inverse of ``lane_index_of``).
    scenic_lane_of: Dict[LaneIndex, str]
    #: Scenic lane group uid -> its highway-env edge ``(from, to)``.
    edge_of_group: Dict[str, Tuple[str, str]]
    #: uids of the lanes inside intersections (connecting lanes).
    connecting_lanes: FrozenSet[str]
    #: Scenic lane uid -> uids of the lanes a vehicle can continue onto at its end
    #: (intersection connecting lanes, else the Scenic successor).
    successors_of: Dict[str, Tuple[str, ...]]
    #: Map file this was loaded from, if any.
    source: Optional[Path] = None
    #: Problems noticed during conversion (links not representable, ...).
    warnings: Tuple[str, ...] = ()
    _lanes_by_uid: Dict[str, "Lane"] = field(default_factory=dict, repr=False)
    _shoulder_area: Any = field(default=None, repr=False)

    def _uid(self, lane: Union["Lane", str]) -> str:
        return lane if isinstance(lane, str) else lane.uid

    def index_of(self, lane: Union["Lane", str]) -> LaneIndex:
        """highway-env lane index of a Scenic lane (object or uid)."""
        return self.lane_index_of[self._uid(lane)]

    def hw_lane(self, lane: Union["Lane", str]) -> AbstractLane:
        """highway-env lane geometry of a Scenic lane (object or uid)."""
        return self.hw_network.get_lane(self.index_of(lane))

    def scenic_lane(self, index: LaneIndex) -> "Lane":
        """Scenic lane for a highway-env lane index."""
        return self._lanes_by_uid[self.scenic_lane_of[tuple(index)]]

    def is_connecting(self, lane: Union["Lane", str, LaneIndex]) -> bool:
        """Whether a lane (Scenic lane, uid or hw index) lies inside an intersection."""
        if isinstance(lane, tuple):
            lane = self.scenic_lane_of[lane]
        return self._uid(lane) in self.connecting_lanes

    def on_shoulder(self, position_hw: Sequence[float]) -> bool:
        """Whether a highway-env position lies on a Scenic shoulder: an OpenDRIVE ``shoulder``,
        ``parking``, ``stop`` or ``border`` lane (Scenic's ``network.shoulders``). Those lanes are
        not highway-env lanes, but a vehicle standing on them (parked, stopped on the hard
        shoulder) is still on the road."""
        if self._shoulder_area is None:
            polygons = [p for sh in getattr(self.scenic_network, "shoulders", ()) for p in _polygons_of(sh)]
            area = shapely.unary_union(polygons) if polygons else shapely.Polygon()
            shapely.prepare(area)
            self._shoulder_area = area
        if self._shoulder_area.is_empty:
            return False
        x, y = hw_to_scenic_position(float(position_hw[0]), float(position_hw[1]))
        return bool(self._shoulder_area.intersects(shapely.Point(x, y)))

    def route_for(self, lanes: Iterable[Union["Lane", str]]) -> List[LaneIndex]:
        """highway-env route (list of lane indexes) through a sequence of Scenic lanes."""
        return [self.index_of(lane) for lane in lanes]

    def next_lanes(self, lane: Union["Lane", str, LaneIndex]) -> List[LaneIndex]:
        """highway-env indexes of the lanes following a lane (see ``successors_of``)."""
        if isinstance(lane, tuple):
            lane = self.scenic_lane_of[lane]
        return [self.lane_index_of[u] for u in self.successors_of[self._uid(lane)]]


def scenic_successors(lane: "Lane") -> List["Lane"]:
    """Lanes a vehicle can drive onto at the end of a Scenic lane.

    These are, for each maneuver, its connecting lane through an intersection or
    else its end lane; a lane without maneuvers falls back to its ``successor``.
    Order is stable (Scenic's maneuver order) and without duplicates.
    """
    out: List[Any] = []
    seen = set()

    def add(candidate: Any) -> None:
        if candidate is not None and hasattr(candidate, "centerline") and candidate.uid not in seen:
            seen.add(candidate.uid)
            out.append(candidate)

    for maneuver in getattr(lane, "maneuvers", ()) or ():
        add(maneuver.connectingLane if maneuver.connectingLane is not None else maneuver.endLane)
    if not out:
        add(getattr(lane, "_successor", None))
    return out


class _UnionFind:
    def __init__(self) -> None:
        self.parent: Dict[Any, Any] = {}

    def find(self, x: Any) -> Any:
        self.parent.setdefault(x, x)
        root = x
        while self.parent[root] != root:
            root = self.parent[root]
        while self.parent[x] != root:
            self.parent[x], x = root, self.parent[x]
        return root

    def union(self, a: Any, b: Any) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[rb] = ra


@dataclass
class _LaneInfo:
    lane: Any
    group: Any
    polyline: Polyline
    width: float
    width_s: np.ndarray
    width_v: np.ndarray
    connecting: bool
    at_start: bool
    at_end: bool
    speed_limit: float


def _centerline_points(lane: Any) -> np.ndarray:
    """Scenic centerline vertices in highway-env coordinates, ``(n, 2)``."""
    geom = lane.centerline.lineString
    if geom.geom_type == "MultiLineString":
        coords = [c for part in geom.geoms for c in part.coords]
    else:
        coords = list(geom.coords)
    pts = np.asarray(coords, dtype=float)[:, :2].copy()
    pts[:, 1] *= -1.0  # envs.coordinates.scenic_to_hw_position, vectorised
    return dedupe_vertices(pts)


def _width_profile(lane: Any, length: float) -> Tuple[np.ndarray, np.ndarray]:
    """``(s, width)`` samples of a Scenic lane (distance centerline -> both edges)."""
    n = int(min(max(math.ceil(length / 2.0) + 1, 3), 101))
    s = np.linspace(0.0, length, n)
    line = lane.centerline.lineString
    pts = shapely.line_interpolate_point(line, s)
    w = shapely.distance(lane.leftEdge.lineString, pts) + shapely.distance(lane.rightEdge.lineString, pts)
    w = np.asarray(w, dtype=float)
    if not np.all(np.isfinite(w)) or np.all(w <= 0):
        w = np.full(n, AbstractLane.DEFAULT_WIDTH)
    return s, w


def _section_positions(road: Any) -> Dict[int, int]:
    """id(lane section) -> index of its road section along the road."""
    out: Dict[int, int] = {}
    for k, section in enumerate(getattr(road, "sections", ()) or ()):
        for lane_section in getattr(section, "lanes", ()) or ():
            out[id(lane_section)] = k
    return out


def _group_extent_flags(lane: Any, group: Any, positions: Dict[int, int], n_sections: int) -> Tuple[bool, bool]:
    """Whether a lane starts at its group's start / ends at its group's end."""
    idx = {positions.get(id(sec)) for sec in getattr(lane, "sections", ()) or ()}
    idx.discard(None)
    if not idx or n_sections == 0:
        return True, True
    forward = group is getattr(lane.road, "forwardLanes", None)
    first, last = (0, n_sections - 1) if forward else (n_sections - 1, 0)
    return first in idx, last in idx


def _lateral_offset(reference: Polyline, line: Polyline) -> Tuple[float, float, float]:
    """Median lateral offset of ``line`` w.r.t. ``reference`` and its s-range on it."""
    fractions = np.linspace(0.05, 0.95, 9)
    samples = [reference.project(line.position(f * line.length, 0.0)) for f in fractions]
    inside = [lat for lon, lat in samples if -0.5 <= lon <= reference.length + 0.5]
    lats = inside if inside else [lat for _, lat in samples]
    s0 = reference.project(line.points[0])[0]
    s1 = reference.project(line.points[-1])[0]
    return float(np.median(lats)), min(s0, s1), max(s0, s1)


def _is_straight(line: Polyline) -> bool:
    chord = line.points[-1] - line.points[0]
    chord_len = float(np.hypot(*chord))
    if chord_len < _MIN_LENGTH:
        return False
    u = chord / chord_len
    rel = line.points - line.points[0]
    deviation = np.abs(rel[:, 0] * u[1] - rel[:, 1] * u[0])
    along = rel @ u
    return (
        float(deviation.max()) <= STRAIGHT_TOLERANCE
        and bool(np.all(np.diff(along) > 0.0))
        and line.length - chord_len <= 1e-3 * line.length
    )


def _speed_limit(lane: Any, speed_limits: Optional[Dict[str, float]]) -> float:
    for element in (lane, getattr(lane, "group", None), getattr(lane, "road", None)):
        value = getattr(element, "speedLimit", None)
        if value is not None:
            return float(value)
    if speed_limits:
        road_id = getattr(getattr(lane, "road", None), "id", None)
        if road_id is not None and str(road_id) in speed_limits:
            return speed_limits[str(road_id)]
    return DEFAULT_SPEED_LIMIT


def _collect_lanes(network: "Network") -> Tuple[List[Any], FrozenSet[str]]:
    """All lanes exactly once, plus the uids of intersection connecting lanes."""
    lanes: Dict[str, Any] = {}
    for lane in network.lanes:
        lanes.setdefault(lane.uid, lane)
    connecting = set()
    for road in getattr(network, "connectingRoads", ()) or ():
        for lane in road.lanes:
            connecting.add(lane.uid)
            lanes.setdefault(lane.uid, lane)
    for intersection in getattr(network, "intersections", ()) or ():
        for maneuver in intersection.maneuvers:
            lane = maneuver.connectingLane
            if lane is not None:
                connecting.add(lane.uid)
                lanes.setdefault(lane.uid, lane)
    return list(lanes.values()), frozenset(connecting)


def convert_network(
    network: "Network",
    *,
    speed_limits: Optional[Dict[str, float]] = None,
    source: Optional[Path] = None,
) -> ConvertedNetwork:
    """Convert a Scenic driving-domain ``Network`` into a highway-env road network.

    Every Scenic lane (ordinary and intersection connecting lanes) becomes one
    highway-env lane; see the module docstring for the edge/node scheme.

    :param network: a Scenic ``scenic.domains.driving.roads.Network``.
    :param speed_limits: optional OpenDRIVE road id -> speed limit [m/s], used when
        Scenic has no ``speedLimit`` for a lane (Scenic does not read them).
    :param source: map file the network came from, recorded on the result.
    :return: the highway-env network and the Scenic <-> highway-env lookup tables.
    """
    lanes, connecting = _collect_lanes(network)
    problems: List[str] = []
    infos = _lane_infos(lanes, connecting, speed_limits, problems)
    uf, groups, successors_of = _join_group_ends(infos, problems)
    edge_of_group = _number_nodes(network, uf, groups)
    hw_network, lane_index_of, scenic_lane_of = _place_lanes(infos, edge_of_group)

    for message in problems:
        logger.debug("road network conversion: %s", message)

    return ConvertedNetwork(
        hw_network=hw_network,
        scenic_network=network,
        lane_index_of=lane_index_of,
        scenic_lane_of=scenic_lane_of,
        edge_of_group=edge_of_group,
        connecting_lanes=connecting,
        successors_of=successors_of,
        source=source,
        warnings=tuple(problems),
        _lanes_by_uid={uid: info.lane for uid, info in infos.items()},
    )


def _lane_polyline(lane: Any, problems: List[str]) -> Polyline:
    """A lane's centerline as a polyline; a degenerate one (all vertices coincide) becomes a tiny stub along
    the lane's heading, noted in ``problems``."""
    pts = _centerline_points(lane)
    if len(pts) < 2:  # all vertices coincide: keep a tiny stub along the lane heading
        first = lane.centerline.lineString.coords[0]
        heading = scenic_to_hw_heading(lane.orientation[(first[0], first[1])].yaw)
        p0 = pts[0] if len(pts) else np.zeros(2)
        pts = np.array([p0, p0 + _MIN_LENGTH * np.array([math.cos(heading), math.sin(heading)])])
        problems.append(f"lane {lane.uid} has a degenerate centerline; using a {_MIN_LENGTH} m stub")
    return Polyline(pts)


def _lane_infos(lanes: List[Any], connecting: FrozenSet[str], speed_limits: Optional[Dict[str, float]],
                problems: List[str]) -> Dict[str, _LaneInfo]:
    """Per-lane geometry: each Scenic lane's polyline, width profile and mean width, whether it spans its
    lane group's start and end, and its speed limit (by lane uid, in Scenic's lane order)."""
    infos: Dict[str, _LaneInfo] = {}
    section_cache: Dict[int, Tuple[Dict[int, int], int]] = {}
    for lane in lanes:
        group = lane.group
        polyline = _lane_polyline(lane, problems)
        width_s, width_v = _width_profile(lane, polyline.length)
        mean_width = float(np.trapezoid(width_v, width_s) / polyline.length) if polyline.length > 0 else float(width_v.mean())
        road = lane.road
        if id(road) not in section_cache:
            positions = _section_positions(road)
            section_cache[id(road)] = (positions, len(getattr(road, "sections", ()) or ()))
        positions, n_sections = section_cache[id(road)]
        at_start, at_end = _group_extent_flags(lane, group, positions, n_sections)
        infos[lane.uid] = _LaneInfo(
            lane=lane,
            group=group,
            polyline=polyline,
            width=mean_width,
            width_s=width_s,
            width_v=width_v,
            connecting=lane.uid in connecting,
            at_start=at_start,
            at_end=at_end,
            speed_limit=_speed_limit(lane, speed_limits),
        )
    return infos


def _join_group_ends(infos: Dict[str, _LaneInfo], problems: List[str]
                     ) -> Tuple["_UnionFind", Dict[str, Any], Dict[str, Tuple[str, ...]]]:
    """Which lane-group ends are one node: a lane's end joins its successor's start when they meet (within
    :data:`LINK_TOLERANCE`) at the ends of both groups; other links are noted in ``problems``.

    Returns the union-find of ``(group uid, "start" | "end")``, the groups by uid and each lane's successors.
    """
    uf = _UnionFind()
    groups: Dict[str, Any] = {}
    for info in infos.values():
        groups.setdefault(info.group.uid, info.group)
        uf.find((info.group.uid, "start"))
        uf.find((info.group.uid, "end"))
    successors_of: Dict[str, Tuple[str, ...]] = {}
    for uid, info in infos.items():
        nexts = [s for s in scenic_successors(info.lane) if s.uid in infos]
        successors_of[uid] = tuple(s.uid for s in nexts)
        for succ in nexts:
            sinfo = infos[succ.uid]
            gap = float(np.hypot(*(info.polyline.points[-1] - sinfo.polyline.points[0])))
            if gap > LINK_TOLERANCE:
                problems.append(
                    f"lane {uid} -> {succ.uid}: end and start are {gap:.2f} m apart; link not in the graph"
                )
                continue
            if not (info.at_end and sinfo.at_start):
                if info.group is not sinfo.group:
                    problems.append(
                        f"lane {uid} -> {succ.uid}: link inside a lane group's extent; not in the graph"
                    )
                continue  # e.g. a lane merging into its neighbour half-way along the group
            uf.union((info.group.uid, "end"), (sinfo.group.uid, "start"))
    return uf, groups, successors_of


def _number_nodes(network: "Network", uf: "_UnionFind", groups: Dict[str, Any]) -> Dict[str, Tuple[str, str]]:
    """Each lane group's edge ``(start node, end node)``, nodes numbered "0", "1", ... in Scenic's lane-group
    order (deterministic)."""
    node_names: Dict[Any, str] = {}

    def node(key: Tuple[str, str]) -> str:
        root = uf.find(key)
        if root not in node_names:
            node_names[root] = str(len(node_names))
        return node_names[root]

    group_order = [g.uid for g in getattr(network, "laneGroups", ())] + sorted(groups)
    edge_of_group: Dict[str, Tuple[str, str]] = {}
    for guid in group_order:
        if guid in groups and guid not in edge_of_group:
            edge_of_group[guid] = (node((guid, "start")), node((guid, "end")))
    return edge_of_group


def _place_lanes(infos: Dict[str, _LaneInfo], edge_of_group: Dict[str, Tuple[str, str]]
                 ) -> Tuple["IndexedRoadNetwork", Dict[str, LaneIndex], Dict[LaneIndex, str]]:
    """The highway-env network: each edge's lanes ordered left to right (by lateral offset from the edge's
    longest lane), with their line types; and the lane-index look-ups both ways."""
    edges: Dict[Tuple[str, str], List[str]] = {}
    for uid, info in infos.items():
        edges.setdefault(edge_of_group[info.group.uid], []).append(uid)

    hw_network = IndexedRoadNetwork()
    lane_index_of: Dict[str, LaneIndex] = {}
    scenic_lane_of: Dict[LaneIndex, str] = {}
    for edge in sorted(edges, key=lambda e: (int(e[0]), int(e[1]))):
        uids = edges[edge]
        reference = max((infos[u].polyline for u in uids), key=lambda pl: pl.length)
        if len(uids) == 1:
            placement = {uids[0]: (0.0, 0.0, reference.length)}
        else:
            placement = {u: _lateral_offset(reference, infos[u].polyline) for u in uids}
        ordered = sorted(uids, key=lambda u: (placement[u][0], u))
        for i, uid in enumerate(ordered):
            info = infos[uid]
            line_types = _line_types(i, ordered, infos, placement)
            hw_lane = _make_lane(info, line_types)
            index: LaneIndex = (edge[0], edge[1], i)
            hw_network.add_lane(edge[0], edge[1], hw_lane)
            lane_index_of[uid] = index
            scenic_lane_of[index] = uid
    return hw_network, lane_index_of, scenic_lane_of


def _line_types(
    i: int,
    ordered: List[str],
    infos: Dict[str, _LaneInfo],
    placement: Dict[str, Tuple[float, float, float]],
) -> List[int]:
    """``[left, right]`` line types of the ``i``-th lane (left to right) of an edge."""
    info = infos[ordered[i]]
    if info.connecting:
        return [LineType.NONE, LineType.NONE]

    def neighbour(j: int) -> Optional[str]:
        if 0 <= j < len(ordered):
            other = infos[ordered[j]]
            if other.group is info.group and not other.connecting:
                return ordered[j]
        return None

    def covers(a: str, b: str) -> bool:  # does lane a span lane b's extent?
        return placement[a][1] <= placement[b][1] + 1.0 and placement[a][2] >= placement[b][2] - 1.0

    uid = ordered[i]
    left, right = neighbour(i - 1), neighbour(i + 1)
    left_type = LineType.STRIPED if left is not None else LineType.CONTINUOUS_LINE
    if right is None:
        right_type = LineType.CONTINUOUS_LINE
    else:
        right_type = LineType.NONE if covers(right, uid) else LineType.STRIPED
    return [left_type, right_type]


def _make_lane(info: _LaneInfo, line_types: List[int]) -> AbstractLane:
    line = info.polyline
    constant_width = float(info.width_v.max() - info.width_v.min()) <= WIDTH_TOLERANCE
    common = dict(line_types=line_types, speed_limit=info.speed_limit)
    if constant_width and _is_straight(line):
        return StraightLane(line.points[0], line.points[-1], width=info.width, **common)
    widths = None if constant_width else (info.width_s, info.width_v)
    return PolylineLane(line.points, width=info.width, widths=widths, **common)


# ---------------------------------------------------------------------------
# Look-ups
# ---------------------------------------------------------------------------


def _polygons_of(region: Any) -> List[Any]:
    """Shapely polygons of a Scenic polygonal region (a shoulder)."""
    geom = getattr(region, "polygons", None)
    if geom is None:
        return []
    return list(getattr(geom, "geoms", [geom]))
