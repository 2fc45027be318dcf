"""Scenic behaviours of pedestrians and cyclists at the roadside: cross when the ego is near, stand still.
Name -> (Scenic text, names of the blocks it needs)."""

from __future__ import annotations

from typing import Dict, Tuple

__all__ = ["CROSSING_BEHAVIORS"]

CROSSING_BEHAVIORS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    "CrossWhenEgoNear": ('''\
behavior CrossWhenEgoNear(speed, triggerTime):
    # step off the kerb once the ego is about triggerTime seconds away, then keep walking
    while (distance from self to ego) > max(7, triggerTime * ego.speed):
        wait
    while True:
        take SetWalkingSpeedAction(speed)
''', ()),
    "RideAcrossWhenEgoNear": ('''\
behavior RideAcrossWhenEgoNear(speed, triggerTime):
    # a cyclist waiting at the roadside rides straight across once the ego is about triggerTime seconds away
    while (distance from self to ego) > max(9, triggerTime * ego.speed):
        take SetThrottleAction(0), SetBrakeAction(1)
    while True:
        throttle = 0.7 if self.speed < speed else 0
        take SetThrottleAction(throttle), SetBrakeAction(0), SetSteerAction(0)
''', ()),
    "StandStill": ('''\
behavior StandStill():
    while True:
        take SetWalkingSpeedAction(0)
''', ()),
}
