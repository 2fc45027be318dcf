"""The lanes of a converted network and its closest-lane look-up: the polyline geometry a curved Scenic lane keeps
(:class:`Polyline`, :class:`PolylineLane`) and the ``RoadNetwork`` that finds a vehicle's lane by pruning far-away
lanes first (:class:`IndexedRoadNetwork`)."""

from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np
from highway_env.road.lane import (
    AbstractLane,
    LineType,
    PolyLaneFixedWidth,
    StraightLane,
)
from highway_env.road.road import RoadNetwork

from envs.road_network.errors import MapLoadError

__all__ = ["LaneIndex", "dedupe_vertices", "Polyline", "PolylineLane", "IndexedRoadNetwork"]

LaneIndex = Tuple[str, str, int]
"""highway-env lane index ``(from_node, to_node, lane_id)``."""


# ---------------------------------------------------------------------------
# Polyline geometry helpers
# ---------------------------------------------------------------------------


def dedupe_vertices(points: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Drop consecutive (near) duplicate vertices."""
    if len(points) < 2:
        return points
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > eps
    return points[keep]


_ARTIFACT_SEGMENT = 1.0
"""Segments shorter than this [m] may be seam artifacts (see :class:`Polyline`)."""

_TINY_SEGMENT = 0.1
"""Segments shorter than this [m] never define the heading themselves."""

_HEADING_WINDOW = 0.5
"""Half-width [m] of the chord used as heading of an artifact segment."""


class Polyline:
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
        pts = dedupe_vertices(np.asarray(points, dtype=float)[:, :2])
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
        self._line = Polyline(np.asarray(lane_points, dtype=float))
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

