"""Section 4 of a straight-road script for one actor: its role picks the function that places it."""

from __future__ import annotations

from typing import Callable, Dict

from dv2s_gym.pipeline.sg.rules.frame import KIND_SPEEDS, ActorFrame
from dv2s_gym.pipeline.sg.rules.kerb import spawn_puller
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.lane_traffic import place_adjacent, place_follower, place_lead, place_slow_lead
from dv2s_gym.pipeline.sg.rules.lane_vehicles import place_cutter, place_oncoming, place_overtaker, place_ramp
from dv2s_gym.pipeline.sg.rules.pedestrians import spawn_lane_pedestrians
from dv2s_gym.pipeline.sg.rules.placement import driving
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script
from dv2s_gym.pipeline.sg.rules.standing import spawn_far_side, spawn_obstacle, spawn_shoulder

__all__ = ["SPAWNERS", "spawn_lane_actor"]

Spawner = Callable[[Script, ActorFrame, LaneContext, str], None]


def _pedestrians(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
    spawn_lane_pedestrians(s, actor, speed, ctx.road.two_way, ctx.reckless)


def _puller(s: Script, actor: ActorFrame, ctx: LaneContext, speed: str) -> None:
    spawn_puller(s, actor, speed, ctx.road.two_way)


SPAWNERS: Dict[Role, Spawner] = {
    Role.OBSTACLE: spawn_obstacle,
    Role.SHOULDER: spawn_shoulder,
    Role.FAR_SIDE: spawn_far_side,
    Role.CROSSER: _pedestrians,
    Role.ROADSIDE: _pedestrians,
    Role.PULLER: _puller,
    Role.RAMP: driving(place_ramp),
    Role.ONCOMING: driving(place_oncoming),
    Role.CUTTER: driving(place_cutter),
    Role.OVERTAKER: driving(place_overtaker),
    Role.LEAD: driving(place_lead),
    Role.FOLLOWER: driving(place_follower),
    Role.SLOW_LEAD: driving(place_slow_lead),
    Role.ADJACENT: driving(place_adjacent),
}
"""Role -> the function that writes an actor of that role into section 4 (with the speed it drives at)."""


def spawn_lane_actor(s: Script, actor: ActorFrame, ctx: LaneContext) -> None:
    """Place ``actor`` (its role assigned) on the straight road."""
    speed = ctx.ego_speed
    if actor.kind in KIND_SPEEDS:  # a slow kind does not ride at the ego's speed
        speed = s.param(f"{actor.name}_speed", KIND_SPEEDS[actor.kind])
    SPAWNERS[actor.role](s, actor, ctx, speed)
