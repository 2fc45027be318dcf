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
local direction of the lane as their heading (see :class:`~envs.road_network.lanes.Polyline`).
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

The package in modules: the errors (:mod:`.errors`), the lanes and the closest-lane look-up (:mod:`.lanes`), the
conversion and the converted network (:mod:`.conversion`), the reading of a map file with its cache
(:mod:`.loading`). Import the names below from here.
"""

from envs.road_network.conversion import (
    DEFAULT_SPEED_LIMIT,
    LINK_TOLERANCE,
    STRAIGHT_TOLERANCE,
    WIDTH_TOLERANCE,
    ConvertedNetwork,
    convert_network,
    scenic_successors,
)
from envs.road_network.errors import MapLoadError, MapNotFoundError
from envs.road_network.lanes import IndexedRoadNetwork, LaneIndex, PolylineLane
from envs.road_network.loading import load_road_network

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
    "WIDTH_TOLERANCE",
    "LINK_TOLERANCE",
    "DEFAULT_SPEED_LIMIT",
]
