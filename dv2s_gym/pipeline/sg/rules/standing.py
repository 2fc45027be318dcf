"""Actors that stand still on a straight road: obstacles on a lane, a vehicle on the hard shoulder, vehicles
parked at a kerb."""

from __future__ import annotations

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.roads import HIGHWAY_MAPS, PARKING_FAR_KERB, PARKING_KERB, PARKING_STREET, \
    SHOULDER_KERB, at_kerb
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Action, Relation

__all__ = ["spawn_obstacle", "spawn_shoulder", "spawn_far_side"]


def spawn_obstacle(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
    """Obstacles on the lane at the actor's side, ahead of the ego."""
    n = actor.name
    urban = s.frame.map not in HIGHWAY_MAPS  # town speeds and distances
    lane = ctx.lane_of(actor.side)
    gap = s.param(f"{n}_gap", "Range(35, 50)" if urban else "Range(55, 85)")
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        s.spawn += [f"{var} = new Obstacle at {lane}.centerline.pointAlongBy(egoS + {gap} + {3.0 * i}),",
                    "    with width Range(0.8, 1.8), with length Range(0.6, 1.4)"]
        ctx.obstacles.append(var)
    rel = ["ahead_of"] + (["same_lane"] if actor.side == 0 else ["left_of" if actor.side > 0 else "right_of"])
    s.show("obstacle", [], [r for r in rel if r in actor.relations or r == Relation.AHEAD_OF], actor.count)


def spawn_shoulder(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
    """Vehicles standing on the hard shoulder, ahead of the ego."""
    n = actor.name
    gap = s.param(f"{n}_gap", "Range(55, 85)")
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        s.spawn += at_kerb(var, CLASS[actor.kind], f"egoS + {gap} + {14 * i}", SHOULDER_KERB, "HoldStill()")
    s.use("HoldStill")
    s.show(actor.kind, [a for a in actor.actions if a == Action.STOP], ["ahead_of", "right_of"], actor.count)


def spawn_far_side(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
    """Vehicles parked at the far kerb (or, said to be right of the ego, at its own), ahead of the ego."""
    n = actor.name
    cls = CLASS[actor.kind]
    gap = s.param(f"{n}_gap", "Range(25, 40)")
    near = Relation.RIGHT_OF in actor.relations  # parked at the ego's own (right) kerb
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        parking = s.frame.map == PARKING_STREET  # on the parking lane at either kerb
        place = (f"right of {var}Spot by {PARKING_KERB if parking else 'Range(1.4, 1.7)'}, "
                 f"facing {var}Spot.heading,\n    with regionContainedIn everywhere," if near else
                 f"left of {var}Spot by {PARKING_FAR_KERB}, facing roadDirection,\n"
                 "    with regionContainedIn everywhere," if parking else
                 f"left of {var}Spot by Range(2.5, 2.7), facing roadDirection,")
        s.spawn += [f"{var}Spot = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + {gap} + {12 * i}), "
                    "facing roadDirection",
                    f"{var} = new {cls} {place}",
                    "    with speed 0,", "    with behavior HoldStill()"]
    s.use("HoldStill")
    s.show(actor.kind, [a for a in actor.actions if a == Action.STOP], ["ahead_of", "right_of" if near else "left_of"],
           actor.count)
