"""Scenic behaviours of vehicles at junctions: follow a route, brake on it, stop at the entry, wait for a
conflicting vehicle, pull out when the ego is near. Name -> (Scenic text, names of the blocks it needs)."""

from __future__ import annotations

from typing import Dict, Tuple

__all__ = ["ROUTE_BEHAVIORS"]

ROUTE_BEHAVIORS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    "DriveRoute": ('''\
behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)
''', ()),
    "CautiousRoute": ('''\
behavior CautiousRoute(speed, route):
    try:
        do DriveRoute(speed, route)
    interrupt when pathBlocked(self, 3):
        take SetThrottleAction(0), SetBrakeAction(1)
''', ("DriveRoute", "pathBlocked")),
    "RouteThenBrake": ('''\
behavior RouteThenBrake(speed, route, after, lowSpeed, strength):
    try:
        do DriveRoute(speed, route)
    interrupt when simulation().currentTime * simulation().timestep > after:
        while self.speed > lowSpeed + 0.3:
            take SetThrottleAction(0), SetBrakeAction(strength)
        if lowSpeed < 0.5:
            do HoldStill()
        do FollowLaneBehavior(target_speed=lowSpeed)
''', ("DriveRoute", "HoldStill")),
    "StopAtEntry": ('''\
behavior StopAtEntry(speed, route, entry):
    # drive the route and brake to a stop at the junction entry (`entry`: the end of the approach lane)
    do DriveRoute(speed, route) until (distance from self to entry) < 1.5 + self.speed * self.speed / 10
    while self.speed > 0.2:
        take SetThrottleAction(0), SetBrakeAction(1)
''', ("DriveRoute",)),
    "StopForConflict": ('''\
behavior StopForConflict(speed, route, entry, other, otherExit, minWait, maxWait):
    # drive the route, stop at the junction entry, wait at least minWait seconds and until `other` (None: no
    # one) has cleared the ego's way (it is on its exit lane, otherExit, or it is 4 m further from the ego's
    # entry than it came since the ego stopped: it has passed), at most maxWait seconds, then go on
    do StopAtEntry(speed, route, entry)
    waited = 0
    closest = 1000
    cleared = other is None
    while waited < maxWait and (waited < minWait or not cleared):
        if other is not None:
            gap = distance from other to entry
            closest = min(closest, gap)
            cleared = otherExit.containsPoint(other.position) or gap > closest + 4
        take SetThrottleAction(0), SetBrakeAction(1)
        waited += simulation().timestep
    do CautiousRoute(speed, route)
''', ("StopAtEntry", "CautiousRoute")),
    "StopThenGoInto": ('''\
behavior StopThenGoInto(speed, route, entry, other, otherEntry, goTime, minWait):
    # drive the route, stop at the junction entry, then misjudge the gap: go on (at the latest after 6 s) once
    # `other` is about goTime seconds from the junction (otherEntry: the end of its approach lane)
    do StopAtEntry(speed, route, entry)
    waited = 0
    while waited < 6 and (waited < minWait or (distance from other to otherEntry) > max(2, other.speed * goTime - 8)):
        take SetThrottleAction(0), SetBrakeAction(1)
        waited += simulation().timestep
    do DriveRoute(speed, route)
''', ("StopAtEntry", "DriveRoute")),
    "PullOutWhenEgoNear": ('''\
behavior PullOutWhenEgoNear(speed, route, egoEntry, triggerTime):
    # wait at the give-way line until the ego is about triggerTime seconds from the junction
    while (distance from ego to egoEntry) > triggerTime * max(ego.speed, 1):
        take SetThrottleAction(0), SetBrakeAction(1)
    do DriveRoute(speed, route)
''', ("DriveRoute",)),
}
