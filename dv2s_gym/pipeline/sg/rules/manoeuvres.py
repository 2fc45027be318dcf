"""Behaviours of a vehicle that stays on its lane's line: U-turn, swerve, drift, brake, stop, speed up,
change lanes, cruise."""

from __future__ import annotations

from typing import Optional

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.roads import HIGHWAY_MAPS
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script, brake_params
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = ["u_turn", "swerve", "drift", "longitudinal_behavior"]


def u_turn(s: Script, speed: str) -> str:
    """Drive on for 1-2 s, slow to 3-4 m/s and turn round to the left (>= 150 degrees), then follow the lane
    it ends in (the opposite lane on a two-way street)."""
    s.use("UTurnLater")
    return f"UTurnLater({speed}, Range(1.0, 2.0), Range(3, 4), Range(0.9, 1.0))"


def swerve(s: Script, speed: str, actor: Optional[ActorFrame] = None) -> str:
    """A quick sideways move inside the lane and back: no lane change happens.

    The side is the one the text gives, else toward the ego for an actor beside it, else left. At highway
    speed the move is smaller and slower (1.1-1.3 m in 1.2-1.6 s) so that the car does not overshoot into the
    next lane. The ego swerves when something blocks its path (at the latest after 4 s)."""
    detail = actor.details.get(Action.SWERVE, {}) if actor is not None else {}
    side = detail.get("side") or detail.get("target")
    if side not in (Lane.LEFT, Lane.RIGHT) and actor is not None:
        side = "left" if Relation.RIGHT_OF in actor.relations else \
            "right" if Relation.LEFT_OF in actor.relations else None
    sign = "-" if side == Lane.RIGHT else ""
    fast = s.frame.map in HIGHWAY_MAPS
    depth = f"{sign}Range(1.1, 1.3)" if fast else f"{sign}Range(1.2, 1.5)"
    duration = "Range(1.2, 1.6)" if fast else "Range(0.8, 1.2)"
    if actor is not None and actor.kind == ActorKind.EGO:
        s.use("SwerveWhenBlocked")
        return f"SwerveWhenBlocked({speed}, {depth}, {duration})"
    s.use("SwerveAndBack")
    return f"SwerveAndBack({speed}, Range(1.0, 2.0), {depth}, {duration})"


def drift(s: Script, speed: str, side: str, hold: Optional[str]) -> str:
    """A slow drift out of the lane to ``side`` (about 2.1-2.6 m: the centre leaves the lane, the vehicle does not
    reach the next lane's centre), held ``hold`` seconds and steered back, or held for good (``hold`` None)."""
    sign = "-" if side == Lane.RIGHT else ""
    s.use("DriftLater")
    return (f"DriftLater({speed}, Range(0.8, 1.6), {sign}Range(2.1, 2.6), Range(2.5, 3.5), "
            f"{hold if hold is not None else -1}, Range(1.8, 2.4))")


def longitudinal_behavior(s: Script, actor: ActorFrame, speed: str) -> str:
    """Behaviour of a vehicle that stays in its lane: brake, stop, accelerate, change lanes or cruise."""
    if actor.has("u_turn"):
        return u_turn(s, speed)
    if actor.has("swerve"):
        return swerve(s, speed, actor)
    if actor.has("drift"):
        # a vehicle beside the ego drifts toward the ego's lane; one in the ego's lane to the side the text says
        side = "left" if actor.side < 0 else "right" if actor.side > 0 else \
            actor.details.get(Action.DRIFT, {}).get("side") or "right"
        return drift(s, speed, side, hold=None if actor.has("collide") else "Range(2.0, 3.0)")
    if actor.has("lane_change_left") or actor.has("lane_change_right"):
        side = 1 if actor.has("lane_change_left") else -1
        after = s.param(f"{actor.name}_change_after", "Range(0.5, 1.5)" if actor.sudden else "Range(1.0, 2.5)")
        dur = s.param(f"{actor.name}_change_duration", "Range(1.5, 2.2)" if actor.sudden else "Range(2.2, 3.2)")
        s.use("ChangeLanesLater")
        return f"ChangeLanesLater({side}, {speed}, {after}, {dur})"
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        s.use("HoldStill")
        return "HoldStill()"
    if actor.has("brake") or actor.has("stop") or (actor.has("collide") and actor.role == Role.LEAD):
        after, low, strength = brake_params(s, actor)
        s.use("BrakeLater")
        return f"BrakeLater({speed}, {after}, {low}, {strength})"
    if actor.has("accelerate"):
        s.use("SpeedUpLater")
        return f"SpeedUpLater({speed}, Range(0.8, 1.8), {speed} + Range(5, 8))"
    s.use("Cruise")
    return f"Cruise({speed})"
