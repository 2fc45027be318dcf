"""The roles an actor plays in a composed script: where it is placed and how it moves relative to the ego.

Both enums are ``str``-valued: a role compares equal to its name as a plain string (``Role.LEAD == "lead"``)
and formats as that string in warnings (an actor's kind is a ``scenario_bank.elements.ActorKind``).
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Role", "JunctionRole"]


class Role(StrEnum):
    """The role of an actor on a straight road (highway, on-ramp, town street)."""

    LEAD = "lead"
    """In the ego's lane, ahead of it."""
    FOLLOWER = "follower"
    """In the ego's lane, behind it."""
    SLOW_LEAD = "slow_lead"
    """Ahead in the ego's lane, slower than the ego, which overtakes it."""
    ADJACENT = "adjacent"
    """In a lane beside the ego's, same direction."""
    CUTTER = "cutter"
    """From a lane beside the ego's into the ego's lane ahead of it."""
    OVERTAKER = "overtaker"
    """From behind the ego, past it and back into its lane."""
    ONCOMING = "oncoming"
    """In the oncoming lane."""
    RAMP = "ramp"
    """On the on-ramp's acceleration lane, merging into the main lanes."""
    PULLER = "puller"
    """Parked at the kerb (or on the shoulder) beside the ego's lane; pulls (or backs) out."""
    SHOULDER = "shoulder"
    """Standing on the hard shoulder right of the rightmost lane."""
    FAR_SIDE = "far_side"
    """Parked or standing at a kerb (the far one, or the ego's own on the street with parking lanes)."""
    OBSTACLE = "obstacle"
    """A static object on a lane."""
    CROSSER = "crosser"
    """A pedestrian (or a cyclist) crossing the road ahead of the ego."""
    ROADSIDE = "roadside"
    """A pedestrian standing at the roadside."""


class JunctionRole(StrEnum):
    """Where a vehicle at a junction comes from, relative to the ego's approach."""

    ONCOMING = "oncoming"
    FROM_LEFT = "from_left"
    FROM_RIGHT = "from_right"
    CROSSING = "crossing"
    INTO_PATH = "into_path"
    """Turning (or pulling) into the lane the ego drives on in."""
    RING_CUT = "ring_cut"
    """On a roundabout, circulating from the left toward the ego's exit, ahead of it."""
    AHEAD = "ahead"
    BEHIND = "behind"
    ANY = "any"
    """Any other approach."""
