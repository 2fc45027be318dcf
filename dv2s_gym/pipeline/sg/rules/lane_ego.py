"""The ego's behaviour on a straight road (overtake, pull out, U-turn, lane change, swerve, drift, brake, speed
up, cruise)."""

from __future__ import annotations

from typing import Tuple

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.frame import KIND_SPEEDS, ActorFrame, ScenarioFrame
from dv2s_gym.pipeline.sg.rules.manoeuvres import drift, swerve, u_turn
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script, brake_params
from scenario_bank.elements import Action, ActorKind

__all__ = ["ego_lane_behavior"]


def ego_lane_behavior(s: Script, ego: ActorFrame, speed: str, reckless: bool, two_way: bool,
                      frame: ScenarioFrame) -> Tuple[str, bool]:
    """The ego's behaviour (used with ego_policy='scenic') and whether it can be spawned first."""
    cruise = "Cruise" if reckless else "CautiousCruise"
    if ego.has("overtake"):
        target = next((a for a in frame.actors if a.role == Role.SLOW_LEAD), None)
        if target is None:  # bypassing something that stands in the ego's lane
            target = next((a for a in frame.actors if a.role == Role.OBSTACLE and a.side == 0 and a.count == 1), None)
        if target is not None:
            s.use("OvertakeAndReturn")
            side = -1 if ego.details.get(Action.OVERTAKE, {}).get("side") == Lane.RIGHT and not two_way else 1
            return (f"OvertakeAndReturn({target.name}, {side}, {speed}, Range(20, 26), Range(8, 12), "
                    f"Range(2.0, 2.8), {speed})"), False
        s.warnings.append("the ego overtakes, but nothing to overtake was described: the overtake is not placed")
        ego.actions.remove("overtake")
    passer = next((a for a in frame.actors if a.role == Role.FOLLOWER and a.has("collide") and a.count == 1), None)
    if (ego.has("pull_out") or ego.has("reverse")) and ego.has("collide") and passer is not None and two_way:
        # it backs up, then pulls out into the side of the vehicle coming along the lane from behind
        s.use("BackUpThenPullOutInto")
        back = "Range(2.5, 3.5)" if ego.has("reverse") else "0.2"
        trigger = "Range(5.5, 7.0)" if passer.kind not in KIND_SPEEDS else "Range(3.0, 4.0)"
        return (f"BackUpThenPullOutInto(egoLane.centerline, {speed}, {back}, {passer.name}, {trigger}, "
                "Range(2.5, 3.5))"), False
    if ego.has("pull_out") or ego.has("reverse"):
        s.use("PullOutWhenNear")
        back = "Range(2.5, 3.5)" if ego.has("reverse") else "0"
        return (f"PullOutWhenNear(egoLane.centerline, 0, {speed}, -Range(0.8, 1.5), {back}, "
                "Range(2.5, 3.5))"), False
    if ego.has("u_turn"):
        return u_turn(s, speed), True
    if (ego.has("lane_change_left") or ego.has("lane_change_right")) and ego.has("drift"):
        # it changes lanes and overshoots: on past the new lane's centre and out of that lane too
        sign = "" if ego.has("lane_change_left") else "-"
        s.use("DriftLater")
        return (f"DriftLater({speed}, Range(0.8, 1.6), {sign}(3.5 + Range(2.1, 2.6)), Range(3.5, 4.5), -1, "
                "Range(1.8, 2.4))"), True
    if ego.has("lane_change_left") or ego.has("lane_change_right"):
        side = 1 if ego.has("lane_change_left") else -1
        after = s.param("ego_change_after", "Range(0.5, 1.5)" if ego.sudden else "Range(1.0, 2.5)")
        dur = s.param("ego_change_duration", "Range(1.5, 2.2)" if ego.sudden else "Range(2.2, 3.2)")
        s.use("ChangeLanesLater")
        return f"ChangeLanesLater({side}, {speed}, {after}, {dur})", True
    if ego.has("swerve"):
        return swerve(s, speed, ego), True
    if ego.has("drift"):
        oncoming = any(a.role == Role.ONCOMING for a in frame.actors)
        if two_way and oncoming and ego.details.get(Action.DRIFT, {}).get("side") != Lane.RIGHT:
            # across the centre line into the oncoming vehicle's path
            s.use("DriftAndReturn")
            return (f"DriftAndReturn({speed}, 1000, Range(2.0, 2.8), Range(1.5, 2.5), -1, Range(1.2, 2.0))", True)
        side = ego.details.get(Action.DRIFT, {}).get("side") or ("left" if oncoming else "right")
        return drift(s, speed, side, hold=None), True
    if ego.has("brake") or ego.has("stop") and not _something_stops_ego(frame):
        s.use("CautiousBrakeLater" if not reckless else "BrakeLater")
        after, low, strength = brake_params(s, ego)
        name = "CautiousBrakeLater" if not reckless else "BrakeLater"
        return f"{name}({speed}, {after}, {low}, {strength})", True
    if ego.has("accelerate"):
        s.use("SpeedUpLater")
        return f"SpeedUpLater({speed}, Range(1.0, 2.0), {speed} + Range(5, 8))", True
    s.use(cruise)
    return f"{cruise}({speed})", True


def _something_stops_ego(frame: ScenarioFrame) -> bool:
    return any(a.kind == ActorKind.OBSTACLE and a.side == 0 or a.role == Role.LEAD and a.has("stop") for a in frame.actors)
