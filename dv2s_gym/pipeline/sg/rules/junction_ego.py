"""The ego at a junction: its behaviour (wait for a crossing vehicle, misjudge it, brake, drive its route) and
its lines in section 4."""

from __future__ import annotations

from typing import List, Optional

from dv2s_gym.pipeline.sg.rules.junction_roles import MANEUVER_TYPES
from dv2s_gym.pipeline.sg.rules.junction_timing import JunctionTiming
from dv2s_gym.pipeline.sg.rules.script import Script, brake_params

__all__ = ["junction_ego_lines"]


def junction_ego_lines(s: Script, t: JunctionTiming, default_ego: Optional[str], reckless: bool) -> List[str]:
    """Section 4's lines for the ego on its route through the junction."""
    ego, ego_speed, conflict = s.frame.ego, t.ego_speed, t.conflict
    if t.misjudges and conflict is not None:
        s.use("StopThenGoInto")
        var = conflict.name if conflict.count == 1 else f"{conflict.name}_1"
        # a left turn meets the other vehicle in the far half of the junction: it goes earlier
        go_time = "Range(3.2, 3.6)" if default_ego == "LEFT_TURN" else "Range(2.6, 3.0)"
        ego_behavior = (f"StopThenGoInto({ego_speed}, egoRoute, egoEntry, {var}, "
                        f"{conflict.name}Maneuver.startLane.centerline.end, {go_time}, Range(0.6, 1.0))")
        _shows_its_maneuver(ego, default_ego)
    elif t.yields:
        s.use("StopForConflict")
        other, exit_lane = "None", "None"
        if conflict is not None:
            var = conflict.name if conflict.count == 1 else f"{conflict.name}_{conflict.count}"
            other, exit_lane = var, f"{conflict.name}Maneuver.endLane"
        ego_behavior = (f"StopForConflict({ego_speed}, egoRoute, egoEntry, {other}, {exit_lane}, Range(0.6, 1.0), "
                        "Range(4, 5))")
        # it goes on through the junction after the stop: straight unless the text says a turn
        _shows_its_maneuver(ego, default_ego)
    elif ego.has("brake") or ego.has("stop"):
        after, low, strength = brake_params(s, ego)
        s.use("RouteThenBrake")
        ego_behavior = f"RouteThenBrake({ego_speed}, egoRoute, {after}, {low}, {strength})"
    else:
        name = "DriveRoute" if reckless else "CautiousRoute"
        s.use(name)
        ego_behavior = f"{name}({ego_speed}, egoRoute)"
    return [f"ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-{t.ego_dist}),",
            f"    with speed {ego_speed},",
            "    with route egoRoute,",
            f"    with behavior {ego_behavior}"]


def _shows_its_maneuver(ego, default_ego: Optional[str]) -> None:
    if default_ego is not None and not any(MANEUVER_TYPES.get(a) == default_ego for a in ego.actions):
        ego.actions.append(str({v: k for k, v in MANEUVER_TYPES.items()}[default_ego]))
