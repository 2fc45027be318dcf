"""Dimensions of the shipped maps, shared by the map builder and by whatever places things on the maps.

:mod:`scenario_bank.maps.build_maps` lays the maps out with these; the rule-based Scenario Generator
places actors with them (kerbs, parking lanes, the roundabout's ring). This module imports nothing.
"""

__all__ = ["LANE_WIDTH", "SIDEWALK_WIDTH", "PARKING_WIDTH", "ROUNDABOUT_RING_RADIUS", "ROUNDABOUT_ARM_START"]

LANE_WIDTH = 3.5
"""Default driving-lane width in metres."""

SIDEWALK_WIDTH = 2.0
"""Width of a sidewalk in metres."""

PARKING_WIDTH = 2.5
"""Width of a kerbside parking lane (``urban_parking``) in metres."""

ROUNDABOUT_RING_RADIUS = 12.0
"""Radius [m] of the ring's reference line (the inner edge of its single lane, the central island's kerb)."""

ROUNDABOUT_ARM_START = 24.0
"""Distance [m] from the centre at which the approach arms start."""
