"""Convert a Scenic road network into a highway-env ``RoadNetwork``.

Any map Scenic can parse (OpenDRIVE ``.xodr``) is converted the same way; there
is nothing per-template in here.

Graph scheme
------------
highway-env names a lane by ``(from_node, to_node, index)``; lanes that share a
``(from, to)`` edge are side lanes of each other (lane changes go to
``index +- 1``) and, at the end of a lane, ``RoadNetwork.next_lane`` continues on
an edge leaving ``to_node``. We therefore build:

* **one edge per Scenic** ``LaneGroup`` (the lanes of one road going one way,
  including the lane groups of the connecting roads inside intersections). Every
  Scenic lane of the group is one highway-env lane of that edge, following the
  lane's whole centerline. Lanes are ordered left (index 0) to right in the
  driving direction, measured geometrically, which gives highway-env's
  convention (a vehicle going ``+x`` sees lane 0 at the top of the screen).
* **nodes are group ends glued by lane links.** Each group has a start and an end
  node; whenever a lane that reaches the end of its group continues (Scenic
  ``successor`` or an intersection maneuver's connecting lane) into a lane that
  starts at the start of its group, those two nodes are merged (union-find). So
  the end node of an incoming road is the start node of all its intersection
  connecting lanes, whose end node is the start node of the outgoing road, and
  routes through intersections work with ``next_lane``.

Lanes of a group need not span the whole group (OpenDRIVE lane sections can add
or drop lanes, e.g. an acceleration lane). We still keep them in the group's
edge, each with its own true extent, so the lane count and side-lane relations
match Scenic one to one. highway-env copes with that: a lane change is only
possible where the target lane exists (``is_reachable_from`` requires a
longitudinal coordinate inside the lane), and a lane that runs to the group's
end without a successor (a tapering acceleration lane) hands over, at its end,
to the closest lane of the next edge, like highway-env's own merge road. What
the graph cannot express is a lane that *ends half-way along its group* (e.g.
merging into its neighbour: a Scenic successor inside the same group). That
link is kept in :attr:`ConvertedNetwork.successors_of` but not in the graph; a
highway-env vehicle still on such a lane at its end is handed to the closest
lane of the edges after the group's end node, so vehicles should change lanes
before (MOBIL/IDM vehicles do, as the ending lane's neighbour is a side lane).

If two different lane groups (e.g. two connecting roads of a junction joining
the same pair of roads) end up between the same pair of nodes, they share that
edge and are ordered left to right together.

Geometry
--------
Centerlines are converted with :mod:`envs.coordinates` (``y`` flipped). A lane
whose centerline is straight within :data:`STRAIGHT_TOLERANCE` and whose width
is constant becomes a :class:`~highway_env.road.lane.StraightLane` (cheap
look-ups); every other lane becomes a :class:`PolylineLane`, a
:class:`~highway_env.road.lane.PolyLaneFixedWidth` that follows the Scenic
polyline exactly (same vertices, hence the same length) and projects positions
onto its nearest segment with numpy, which is faster than highway-env's
1 m-resampled spline and stays correct on U-turns. Scenic centerlines carry
centimetre-long seam segments (some pointing backwards) where lane sections or
plan-view geometries were chained; they are kept for the length but take the
local direction of the lane as their heading (see :class:`_Polyline`).
Widths are measured from the Scenic lane edges; lanes whose width varies by more
than :data:`WIDTH_TOLERANCE` (e.g. a tapering acceleration lane) keep the
sampled width profile (``width_at``), others get their mean width.

Line types: ``STRIPED`` between same-direction neighbours, ``CONTINUOUS_LINE`` on
the outer edges of a group (curb side and next to opposing traffic), ``NONE``
on both sides of intersection connecting lanes. As in highway-env's own roads,
a boundary shared by two lanes is drawn once (by the right-hand lane's left
line) unless the neighbours do not cover each other.

The returned ``hw_network`` is an :class:`IndexedRoadNetwork`, a
``RoadNetwork`` whose ``get_closest_lane_index`` (called by every vehicle on
every step) returns exactly the same lane as highway-env's linear scan but prunes
far-away lanes with a bounding-box lower bound first.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import xml.etree.ElementTree as ET
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
    PolyLaneFixedWidth,
    StraightLane,
)
from highway_env.road.road import RoadNetwork

from envs.coordinates import (
    hw_to_scenic_position,
    scenic_to_hw_heading,
)
from envs.errors import DV2SError
from scenario_bank.map_cache import load_network

if TYPE_CHECKING:  # pragma: no cover - typing only
    from scenic.domains.driving.roads import Lane, Network

__all__ = [
    "LaneIndex",
    "MapLoadError",
    "MapNotFoundError",
    "PolylineLane",
    "IndexedRoadNetwork",
    "ConvertedNetwork",
    "convert_network",
    "load_road_network",
    "scenic_successors",
    "STRAIGHT_TOLERANCE",
]

logger = logging.getLogger(__name__)

LaneIndex = Tuple[str, str, int]
"""highway-env lane index ``(from_node, to_node, lane_id)``."""

STRAIGHT_TOLERANCE = 0.05
"""Max distance [m] of a centerline vertex from its chord for a ``StraightLane``."""

WIDTH_TOLERANCE = 0.25
"""Max width variation [m] along a lane for a constant-width ``StraightLane``."""

LINK_TOLERANCE = 2.0
"""Max gap [m] between a lane's end and its successor's start to join their nodes."""

DEFAULT_SPEED_LIMIT = 20.0
"""Speed limit [m/s] used when neither Scenic nor the map file gives one (highway-env's default)."""

_MIN_LENGTH = 1e-3


class MapLoadError(DV2SError, ValueError):
    """A road network map could not be loaded (parse error, no drivable lanes...)."""


class MapNotFoundError(MapLoadError, FileNotFoundError):
    """The road network map file does not exist (also a ``FileNotFoundError``)."""


# ---------------------------------------------------------------------------
# Polyline geometry helpers
# ---------------------------------------------------------------------------


def _dedupe(points: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Drop consecutive (near) duplicate vertices."""
    if len(points) < 2:
        return points
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > eps
    return points[keep]


_ARTIFACT_SEGMENT = 1.0
"""Segments shorter than this [m] may be seam artifacts (see :class:`_Polyline`)."""

_TINY_SEGMENT = 0.1
"""Segments shorter than this [m] never define the heading themselves."""

_HEADING_WINDOW = 0.5
"""Half-width [m] of the chord used as heading of an artifact segment."""


class _Polyline:
    """Arc-length parametrised polyline with nearest-segment projection (numpy).

    Positions follow the given vertices exactly, so the length and the
    arc-length parametrisation are those of the input. Headings (and the lateral
    axis) are per segment, except on seam artifacts: Scenic chains the
    centerlines of lane sections / plan-view geometries, which leaves
    centimetre-long segments at the seams, some pointing backwards. A segment
    shorter than :data:`_TINY_SEGMENT`, or shorter than
    :data:`_ARTIFACT_SEGMENT` and pointing against the local direction of travel,
    takes the direction of the chord spanning +-:data:`_HEADING_WINDOW` around it.
    """

    __slots__ = ("points", "starts", "dirs", "hdirs", "normals", "seg_len", "cum", "length", "headings")

    def __init__(self, points: np.ndarray) -> None:
        pts = _dedupe(np.asarray(points, dtype=float)[:, :2])
        if len(pts) < 2:
            raise MapLoadError("polyline needs at least two distinct points")
        seg = np.diff(pts, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self.points = pts
        self.starts = pts[:-1]
        self.dirs = seg / seg_len[:, None]
        self.seg_len = seg_len
        self.cum = np.concatenate(([0.0], np.cumsum(seg_len)))
        self.length = float(self.cum[-1])
        heading_dirs = self.dirs.copy()
        for i in np.flatnonzero(seg_len < _ARTIFACT_SEGMENT):
            mid = self.cum[i] + 0.5 * seg_len[i]
            lo = max(mid - _HEADING_WINDOW, 0.0)
            hi = min(mid + _HEADING_WINDOW, self.length)
            chord = self._point(hi) - self._point(lo)
            norm = float(np.hypot(chord[0], chord[1]))
            if norm < 1e-9:
                continue
            chord /= norm
            if seg_len[i] < _TINY_SEGMENT or float(chord @ self.dirs[i]) < 0.0:
                heading_dirs[i] = chord
        self.hdirs = heading_dirs
        # highway-env lateral axis: +90 deg from the direction in its (y-down) frame.
        self.normals = np.column_stack((-heading_dirs[:, 1], heading_dirs[:, 0]))
        self.headings = np.arctan2(heading_dirs[:, 1], heading_dirs[:, 0])

    def _point(self, s: float) -> np.ndarray:
        i = self.segment_at(s)
        return self.starts[i] + (s - self.cum[i]) * self.dirs[i]

    def segment_at(self, s: float) -> int:
        i = int(np.searchsorted(self.cum, s, side="right")) - 1
        return min(max(i, 0), len(self.seg_len) - 1)

    def position(self, s: float, r: float) -> np.ndarray:
        if s < 0.0:
            return self.points[0] + s * self.hdirs[0] + r * self.normals[0]
        if s > self.length:
            return self.points[-1] + (s - self.length) * self.hdirs[-1] + r * self.normals[-1]
        i = self.segment_at(s)
        return self.starts[i] + (s - self.cum[i]) * self.dirs[i] + r * self.normals[i]

    def heading(self, s: float) -> float:
        return float(self.headings[self.segment_at(s)])

    def project(self, position: np.ndarray) -> Tuple[float, float]:
        """``(longitudinal, lateral)`` of a point; extrapolates past both ends."""
        p = np.asarray(position, dtype=float)[:2]
        d = p - self.starts
        t = d[:, 0] * self.dirs[:, 0] + d[:, 1] * self.dirs[:, 1]
        tc = np.clip(t, 0.0, self.seg_len)
        fx = d[:, 0] - tc * self.dirs[:, 0]
        fy = d[:, 1] - tc * self.dirs[:, 1]
        i = int(np.argmin(fx * fx + fy * fy))
        last = len(self.seg_len) - 1
        if i == 0 and tc[0] <= 0.0:  # before the start: extrapolate along the first heading
            along = float(d[0] @ self.hdirs[0])
            if along < 0.0:
                return along, float(d[0] @ self.normals[0])
        if i == last and tc[last] >= self.seg_len[last]:  # past the end
            e = p - self.points[-1]
            along = float(e @ self.hdirs[last])
            if along > 0.0:
                return self.length + along, float(e @ self.normals[last])
        lateral = d[i, 0] * self.normals[i, 0] + d[i, 1] * self.normals[i, 1]
        return float(self.cum[i] + tc[i]), float(lateral)

    def max_turn(self) -> float:
        """Largest heading change [rad] at an interior vertex."""
        if len(self.headings) < 2:
            return 0.0
        diff = np.diff(self.headings)
        return float(np.max(np.abs((diff + np.pi) % (2 * np.pi) - np.pi)))


# ---------------------------------------------------------------------------
# highway-env lane and network classes
# ---------------------------------------------------------------------------


class PolylineLane(PolyLaneFixedWidth):
    """A lane that follows a polyline exactly, with an optional width profile.

    Drop-in for :class:`~highway_env.road.lane.PolyLaneFixedWidth` (it is one),
    but positions, headings and Frenet coordinates are computed on the given
    vertices themselves (piecewise-linear, heading constant per segment) with a
    vectorised nearest-segment projection. Coordinates extrapolate linearly
    before the start and after the end, like ``StraightLane``.

    :param lane_points: centerline vertices in highway-env coordinates.
    :param width: nominal (mean) width [m], also returned by ``width_at`` when no
        profile is given.
    :param widths: optional ``(s, width)`` samples; ``width_at`` interpolates them.
    """

    def __init__(
        self,
        lane_points: Sequence[Tuple[float, float]],
        width: float = AbstractLane.DEFAULT_WIDTH,
        line_types: Optional[Sequence[int]] = None,
        forbidden: bool = False,
        speed_limit: float = 20,
        priority: int = 0,
        widths: Optional[Tuple[Sequence[float], Sequence[float]]] = None,
    ) -> None:
        # Deliberately not calling PolyLaneFixedWidth.__init__: its 1 m spline
        # resampling is what this class replaces (and it fails below 1 m).
        self._line = _Polyline(np.asarray(lane_points, dtype=float))
        self.length = self._line.length
        self.width = float(width)
        self.line_types = list(line_types) if line_types is not None else [LineType.STRIPED, LineType.STRIPED]
        self.forbidden = forbidden
        self.speed_limit = speed_limit
        self.priority = priority
        if widths is not None:
            ws = np.asarray(widths[0], dtype=float)
            wv = np.asarray(widths[1], dtype=float)
            self._width_s: Optional[np.ndarray] = ws if len(ws) > 1 else None
            self._width_v: Optional[np.ndarray] = wv if len(ws) > 1 else None
        else:
            self._width_s = self._width_v = None

    @property
    def points(self) -> np.ndarray:
        """The centerline vertices (highway-env frame), shape ``(n, 2)``."""
        return self._line.points

    def position(self, longitudinal: float, lateral: float) -> np.ndarray:
        return self._line.position(float(longitudinal), float(lateral))

    def local_coordinates(self, position: np.ndarray) -> Tuple[float, float]:
        return self._line.project(position)

    def heading_at(self, longitudinal: float) -> float:
        return self._line.heading(float(longitudinal))

    def width_at(self, longitudinal: float) -> float:
        if self._width_s is None:
            return self.width
        return float(np.interp(longitudinal, self._width_s, self._width_v))

    @classmethod
    def from_config(cls, config: dict) -> "PolylineLane":
        return cls(**config)

    def to_config(self) -> dict:
        widths = None
        if self._width_s is not None:
            widths = [self._width_s.tolist(), self._width_v.tolist()]
        return {
            "class_name": self.__class__.__name__,
            "config": {
                "lane_points": self._line.points.tolist(),
                "width": self.width,
                "line_types": list(self.line_types),
                "forbidden": self.forbidden,
                "speed_limit": self.speed_limit,
                "priority": self.priority,
                "widths": widths,
            },
        }


class _ClosestLaneIndex:
    """Bounding boxes and distance factors of every lane of a network."""

    def __init__(self, network: RoadNetwork) -> None:
        self.indexes: List[LaneIndex] = []
        self.lanes: List[AbstractLane] = []
        lo, hi, factor = [], [], []
        for _from, tos in network.graph.items():
            for _to, lanes in tos.items():
                for i, lane in enumerate(lanes):
                    self.indexes.append((_from, _to, i))
                    self.lanes.append(lane)
                    if isinstance(lane, PolylineLane):
                        pts = lane.points
                        # at an interior vertex turning by a, the lane's L1 Frenet
                        # distance is >= cos(a) * the Euclidean distance.
                        factor.append(max(math.cos(min(lane._line.max_turn(), math.pi / 2)), 0.0))
                    elif isinstance(lane, StraightLane):
                        pts = np.array([lane.start, lane.end], dtype=float)
                        factor.append(1.0)
                    else:
                        pts = np.zeros((1, 2))
                        factor.append(0.0)  # unknown geometry: never pruned
                    lo.append(pts.min(axis=0))
                    hi.append(pts.max(axis=0))
        self.lo = np.array(lo, dtype=float).reshape(-1, 2)
        self.hi = np.array(hi, dtype=float).reshape(-1, 2)
        self.factor = np.array(factor, dtype=float)
        # The same boxes as plain floats: on small networks a Python loop is cheaper than NumPy calls.
        self.boxes = [(float(a[0]), float(a[1]), float(b[0]), float(b[1]), float(f))
                      for a, b, f in zip(self.lo, self.hi, self.factor)]

    def lower_bounds(self, x: float, y: float):
        """Lower bound of each lane's ``distance_with_heading`` at ``(x, y)``, as ``[(bound, k), ...]``."""
        if len(self.boxes) > _SMALL_NETWORK:
            dx = np.maximum(np.maximum(self.lo[:, 0] - x, x - self.hi[:, 0]), 0.0)
            dy = np.maximum(np.maximum(self.lo[:, 1] - y, y - self.hi[:, 1]), 0.0)
            # 0.25 m slack covers the centimetre-scale seam artifacts of Scenic centerlines
            bound = np.maximum(np.hypot(dx, dy) - 0.25, 0.0) * self.factor
            return [(bound[k], int(k)) for k in np.argsort(bound, kind="stable")]
        bounds = []
        for k, (lox, loy, hix, hiy, factor) in enumerate(self.boxes):
            dx = max(lox - x, x - hix, 0.0)
            dy = max(loy - y, y - hiy, 0.0)
            bounds.append((max(math.hypot(dx, dy) - 0.25, 0.0) * factor, k))
        bounds.sort()
        return bounds


_SMALL_NETWORK = 32
"""Up to this many lanes, closest-lane bounds are computed in plain Python."""


class IndexedRoadNetwork(RoadNetwork):
    """``RoadNetwork`` with a pruned, exact ``get_closest_lane_index``.

    highway-env's version evaluates ``distance_with_heading`` on every lane of
    the map for every vehicle on every step. For straight and polyline lanes that
    distance is bounded below by (a known fraction of) the Euclidean distance to
    the lane's bounding box, so lanes are visited in order of that bound and the
    scan stops once no remaining lane can beat the best one. The result (ties
    included: the first lane in graph order wins) is the same as highway-env's.
    """

    def __init__(self) -> None:
        super().__init__()
        self._closest_index: Optional[_ClosestLaneIndex] = None

    def add_lane(self, _from: str, _to: str, lane: AbstractLane) -> None:
        super().add_lane(_from, _to, lane)
        self._closest_index = None

    def get_closest_lane_index(
        self, position: np.ndarray, heading: Optional[float] = None
    ) -> LaneIndex:
        index = self._closest_index
        if index is None:
            index = self._closest_index = _ClosestLaneIndex(self)
        p = np.asarray(position, dtype=float)[:2]
        best_d, best_k = math.inf, -1
        for bound, k in index.lower_bounds(float(p[0]), float(p[1])):
            if bound > best_d:
                break
            d = index.lanes[k].distance_with_heading(p, heading)
            if d < best_d or (d == best_d and k < best_k):
                best_d, best_k = d, k
        if best_k < 0:  # empty network or NaN position: defer to highway-env
            return super().get_closest_lane_index(position, heading)
        return index.indexes[best_k]


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
    polyline: _Polyline
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
    return _dedupe(pts)


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


def _lateral_offset(reference: _Polyline, line: _Polyline) -> Tuple[float, float, float]:
    """Median lateral offset of ``line`` w.r.t. ``reference`` and its s-range on it."""
    fractions = np.linspace(0.05, 0.95, 9)
    samples = [reference.project(line.position(f * line.length, 0.0)) for f in fractions]
    inside = [lat for lon, lat in samples if -0.5 <= lon <= reference.length + 0.5]
    lats = inside if inside else [lat for _, lat in samples]
    s0 = reference.project(line.points[0])[0]
    s1 = reference.project(line.points[-1])[0]
    return float(np.median(lats)), min(s0, s1), max(s0, s1)


def _is_straight(line: _Polyline) -> bool:
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


def _lane_polyline(lane: Any, problems: List[str]) -> _Polyline:
    """A lane's centerline as a polyline; a degenerate one (all vertices coincide) becomes a tiny stub along
    the lane's heading, noted in ``problems``."""
    pts = _centerline_points(lane)
    if len(pts) < 2:  # all vertices coincide: keep a tiny stub along the lane heading
        first = lane.centerline.lineString.coords[0]
        heading = scenic_to_hw_heading(lane.orientation[(first[0], first[1])].yaw)
        p0 = pts[0] if len(pts) else np.zeros(2)
        pts = np.array([p0, p0 + _MIN_LENGTH * np.array([math.cos(heading), math.sin(heading)])])
        problems.append(f"lane {lane.uid} has a degenerate centerline; using a {_MIN_LENGTH} m stub")
    return _Polyline(pts)


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


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------

_CACHE: Dict[Tuple[str, int, int], ConvertedNetwork] = {}
_CACHE_LOCK = threading.Lock()

_SPEED_UNITS = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}


def _read_speed_limits(path: Path) -> Dict[str, float]:
    """OpenDRIVE road id -> first ``<type><speed max=...>`` of the road [m/s]."""
    limits: Dict[str, float] = {}
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return limits
    for road in root.iter("road"):
        for road_type in road.findall("type"):
            speed = road_type.find("speed")
            if speed is None:
                continue
            try:
                value = float(speed.get("max", "nan"))
            except ValueError:
                continue
            factor = _SPEED_UNITS.get(speed.get("unit", "m/s"), None)
            if factor is not None and math.isfinite(value) and value > 0:
                limits[str(road.get("id"))] = value * factor
                break
    return limits


def _load_scenic_network(path: Path) -> "Network":
    return load_network(path)


def load_road_network(map_path: Union[str, Path]) -> ConvertedNetwork:
    """Load a map through Scenic and convert it, caching the result in-process.

    Scenic's parsed network is cached in the user cache directory
    (:mod:`scenario_bank.map_cache`), never beside the map. The conversion is cached by resolved path, modification
    time and size, so resetting an environment does not reconvert; the same
    :class:`ConvertedNetwork` object is returned each time.

    :param map_path: path to an OpenDRIVE ``.xodr`` file (anything
        ``Network.fromFile`` accepts).
    :raises MapNotFoundError: (a ``FileNotFoundError``) the file does not exist.
    :raises MapLoadError: (a ``ValueError``) Scenic could not parse the file, or
        it has no drivable lanes.
    """
    path = Path(map_path).expanduser()
    try:
        resolved = path.resolve(strict=True)
        stat = resolved.stat()
    except FileNotFoundError:
        raise MapNotFoundError(
            f"road network map not found: {str(map_path)!r} (looked for {path.absolute()}). "
            "Check the path; relative paths are resolved against the current working "
            f"directory ({os.getcwd()})."
        ) from None
    if not resolved.is_file():
        raise MapLoadError(f"road network map {str(map_path)!r} is not a file ({resolved})")

    where = repr(str(map_path)) if Path(str(map_path)) == resolved else f"{str(map_path)!r} ({resolved})"
    key = (str(resolved), stat.st_mtime_ns, stat.st_size)
    with _CACHE_LOCK:
        cached = _CACHE.get(key)
    if cached is not None:
        return cached

    try:
        network = _load_scenic_network(resolved)
    except FileNotFoundError as exc:
        raise MapNotFoundError(f"road network map {str(map_path)!r} could not be read: {exc}") from exc
    except Exception as exc:  # Scenic raises all sorts of things on bad input
        detail = f"{type(exc).__name__}: {exc}".strip()
        raise MapLoadError(
            f"Scenic could not load the road network {where}: {detail}. Check that the "
            "file is a complete, valid OpenDRIVE (.xodr) map, e.g. open it in an "
            "OpenDRIVE viewer or regenerate it with the tool that wrote it."
        ) from exc

    if not network.lanes:
        raise MapLoadError(
            f"road network {where} contains no drivable lanes. "
            "Check that it is the intended OpenDRIVE map and that its roads have lanes "
            'of type "driving".'
        )
    speed_limits = _read_speed_limits(resolved) if resolved.suffix == ".xodr" else {}
    converted = convert_network(network, speed_limits=speed_limits, source=resolved)
    with _CACHE_LOCK:
        # keep only the newest version of a given file
        for old in [k for k in _CACHE if k[0] == key[0]]:
            del _CACHE[old]
        _CACHE[key] = converted
    return converted
