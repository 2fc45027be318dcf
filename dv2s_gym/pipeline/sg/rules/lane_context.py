"""What placing one actor on a straight road needs besides the actor itself."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List

from dv2s_gym.pipeline.sg.rules.lane_geometry import LaneNames
from dv2s_gym.pipeline.sg.rules.lane_roles import LaneRoad

__all__ = ["LaneContext"]


@dataclass
class LaneContext:
    """The road, the ego's speed and lanes, and what earlier actors took (filled in as actors are placed)."""

    ego_speed: str
    """Scenic expression of the ego's speed."""
    lane_of: LaneNames
    road: LaneRoad
    reckless: bool
    """Someone collides: the ego does not brake for what is in its path."""
    used: Dict[int, int] = field(default_factory=dict)
    """Lane offset -> how many vehicles are placed in it so far."""
    obstacles: List[str] = field(default_factory=list)
    """Scenic names of the obstacles placed so far."""
