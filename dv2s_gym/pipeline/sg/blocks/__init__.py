"""Scenic building blocks of the rule-based Scenario Generator (:mod:`dv2s_gym.pipeline.sg.rules`).

Each block is a piece of Scenic text: behaviours (section 2 of a script), helper
functions for road geometry (section 3) and the header (section 1). The
composer in :mod:`dv2s_gym.pipeline.sg.rules` picks the blocks a description
needs, fills their parameters and glues them into one script.

Conventions every block follows (they were measured on the highway-env model):

* lateral offsets are metres to the left of a centreline
  (``line.signedDistanceTo(point)`` is positive on the left);
* lane changes slide the car sideways relative to the centreline of the lane it
  starts in, so they also work into an opposite-direction lane (overtaking on a
  two-way street) where following that lane would turn the car around;
* conditions on other actors wait 0.4 s first, so nothing fires on the
  simulator's very first step;
* behaviours read only their arguments, ``self``, ``ego`` and the simulation.
"""

from __future__ import annotations

import hashlib
from typing import Dict, Iterable, List, Tuple

__all__ = ["BEHAVIORS", "HELPERS", "WEATHERS", "LANE_WIDTH", "behavior_text", "helper_text", "context_hash"]

LANE_WIDTH = 3.5
"""Lane width of every shipped map [m]."""

WEATHERS = {
    "clear": ["'ClearNoon'", "'ClearSunset'", "'CloudyNoon'"],
    "rain": ["'WetNoon'", "'SoftRainNoon'", "'MidRainyNoon'", "'HardRainNoon'"],
    "night": ["'ClearNight'", "'CloudyNight'", "'WetNight'"],
    "fog": ["'CloudyNoon'", "'WetCloudyNoon'", "'CloudySunset'"],
    "any": ["'ClearNoon'", "'CloudyNoon'", "'WetNoon'", "'ClearSunset'", "'WetCloudySunset'", "'SoftRainNoon'"],
}

# --------------------------------------------------------------------------- helpers (functions)
HELPERS: Dict[str, str] = {
    "pathBlocked": '''\
def pathBlocked(car, margin):
    # something (vehicle, pedestrian, prop) in the car's own corridor that it is closing in on
    for obj in simulation().objects:
        if obj is car:
            continue
        rel = (obj.position - car.position).rotatedBy(-car.heading)
        # where it will be in 1.2 s: someone about to step into the corridor counts already
        soon = (obj.position + obj.velocity * 1.2 - car.position).rotatedBy(-car.heading)
        entering = abs(soon.x) <= 2.3 or rel.x * soon.x < 0
        if rel.y <= 0 or (abs(rel.x) > 2.3 and not entering):
            continue
        closing = (car.velocity - obj.velocity).rotatedBy(-car.heading).y
        if rel.y < margin + 0.35 * car.speed + max(0, closing) * 1.6:
            return True
        if obj.speed < 0.5 and rel.y < margin + 8:
            return True  # stay stopped behind something that stands still
    return False
''',
    "laneSides": '''\
def laneLeftOf(lane):
    section = None if lane is None else lane.sections[0]._laneToLeft
    return None if section is None or section.isForward != lane.sections[0].isForward else section.lane

def laneRightOf(lane):
    section = None if lane is None else lane.sections[0]._laneToRight
    return None if section is None else section.lane

def lanesLeftOf(lane):
    found = []
    lane = laneLeftOf(lane)
    while lane is not None:
        found.append(lane)
        lane = laneLeftOf(lane)
    return found

def lanesRightOf(lane):
    found = []
    lane = laneRightOf(lane)
    while lane is not None:
        found.append(lane)
        lane = laneRightOf(lane)
    return found
''',
    "approach": '''\
def approachDir(lane):
    # direction in which traffic on `lane` drives as it reaches its end (the junction)
    return lane.centerline[-1] - lane.centerline[-2]

def sideOf(a, b):
    # > 0: a car arriving on lane b comes from the right of a driver arriving on lane a
    da = approachDir(a)
    db = approachDir(b)
    return da.x * db.y - da.y * db.x

def opposite(a, b):
    da = approachDir(a)
    db = approachDir(b)
    return da.x * db.x + da.y * db.y < -0.7 * da.norm() * db.norm()
''',
}

# --------------------------------------------------------------------------- behaviours
# name -> (scenic text, names of blocks it needs)
BEHAVIORS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    "CautiousCruise": ('''\
behavior CautiousCruise(speed):
    # keep the lane at `speed` and brake for anything in the path
    try:
        do FollowLaneBehavior(target_speed=speed)
    interrupt when pathBlocked(self, 5):
        take SetThrottleAction(0), SetBrakeAction(1)
''', ("pathBlocked",)),
    "Cruise": ('''\
behavior Cruise(speed):
    do FollowLaneBehavior(target_speed=speed)
''', ()),
    "HoldStill": ('''\
behavior HoldStill():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)
''', ()),
    "BrakeLater": ('''\
behavior BrakeLater(speed, after, lowSpeed, strength):
    # drive on for `after` seconds, then brake with `strength` down to lowSpeed (0: stop and stay)
    do FollowLaneBehavior(target_speed=speed) for after seconds
    while self.speed > lowSpeed + 0.3:
        take SetThrottleAction(0), SetBrakeAction(strength)
    if lowSpeed < 0.5:
        do HoldStill()
    do FollowLaneBehavior(target_speed=lowSpeed)
''', ("HoldStill",)),
    "CautiousBrakeLater": ('''\
behavior CautiousBrakeLater(speed, after, lowSpeed, strength):
    try:
        do BrakeLater(speed, after, lowSpeed, strength)
    interrupt when pathBlocked(self, 5):
        take SetThrottleAction(0), SetBrakeAction(1)
''', ("BrakeLater", "pathBlocked")),
    "SpeedUpLater": ('''\
behavior SpeedUpLater(speed, after, fastSpeed):
    do FollowLaneBehavior(target_speed=speed) for after seconds
    do FollowLaneBehavior(target_speed=fastSpeed)
''', ()),
    "SlideOffset": ('''\
behavior SlideOffset(line, fromOffset, toOffset, speed, duration):
    # track `line` at a lateral offset (m, left positive) that moves smoothly from fromOffset
    # to toOffset within `duration` seconds, then stays there
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    i = 0
    while True:
        i = min(i + 1, steps)
        u = i / steps
        offset = fromOffset + (toOffset - fromOffset) * u * u * (3 - 2 * u)
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - offset)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
''', ()),
    "ChangeLanes": ('''\
behavior ChangeLanes(side, speed, duration):
    # one lane to the left (side 1) or to the right (side -1), then follow the new lane
    line = self.laneSection.centerline
    start = line.signedDistanceTo(self.position)
    do SlideOffset(line, start, side * 3.5, speed, duration) for duration + 0.3 seconds
    do FollowLaneBehavior(target_speed=speed)
''', ("SlideOffset",)),
    "ChangeLanesLater": ('''\
behavior ChangeLanesLater(side, speed, after, duration):
    do FollowLaneBehavior(target_speed=speed) for after seconds
    do ChangeLanes(side, speed, duration)
''', ("ChangeLanes",)),
    "CutInWhenAhead": ('''\
behavior CutInWhenAhead(side, speed, gap, duration, speedAfter):
    # drive past the ego in the next lane, move into its lane once `gap` metres ahead of it
    do FollowLaneBehavior(target_speed=speed) for 0.4 seconds
    do FollowLaneBehavior(target_speed=speed) until (distance past ego of self) > gap
    do ChangeLanes(side, speedAfter, duration)
''', ("ChangeLanes",)),
    "PullInWhenClose": ('''\
behavior PullInWhenClose(side, speed, trigger, duration):
    # a slower vehicle ahead in the next lane moves into the ego's lane once the ego is within `trigger` m
    do FollowLaneBehavior(target_speed=speed) for 0.4 seconds
    do FollowLaneBehavior(target_speed=speed) until (distance past ego of self) < trigger
    do ChangeLanes(side, speed, duration)
''', ("ChangeLanes",)),
    "OvertakeAndReturn": ('''\
behavior OvertakeAndReturn(target, side, speed, pullOut, returnGap, duration, speedAfter):
    # close up on `target` from behind, pull out to `side`, pass it and pull back in returnGap m ahead
    do FollowLaneBehavior(target_speed=speed) for 0.4 seconds
    do FollowLaneBehavior(target_speed=speed) until (distance past target of self) > -pullOut
    homeLine = self.laneSection.centerline
    start = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, start, side * 3.5, speed, duration) until (distance past target of self) > returnGap
    now = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, now, 0, speedAfter, duration) for duration + 0.3 seconds
    do FollowLaneBehavior(target_speed=speedAfter)
''', ("SlideOffset",)),
    "DriftAndReturn": ('''\
behavior DriftAndReturn(speed, trigger, depth, duration, returnTrigger, returnDuration):
    # drift `depth` m sideways (left positive) once near the ego, steer back when closer still
    do FollowLaneBehavior(target_speed=speed) for 0.4 seconds
    do FollowLaneBehavior(target_speed=speed) until (distance from self to ego) < trigger
    homeLine = self.laneSection.centerline
    do SlideOffset(homeLine, 0, depth, speed, duration) until (distance from self to ego) < returnTrigger
    now = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, now, 0, speed, returnDuration) for returnDuration + 0.3 seconds
    do FollowLaneBehavior(target_speed=speed)
''', ("SlideOffset",)),
    "DriftLater": ('''
behavior DriftLater(speed, after, depth, duration, hold, returnDuration):
    # after `after` seconds, drift slowly `depth` m sideways (left positive) out of the lane, stay there
    # `hold` seconds (negative: for good), then steer back to the lane centre
    do FollowLaneBehavior(target_speed=speed) for after seconds
    homeLine = self.laneSection.centerline
    start = homeLine.signedDistanceTo(self.position)
    if hold < 0:
        do SlideOffset(homeLine, start, depth, speed, duration)
    do SlideOffset(homeLine, start, depth, speed, duration) for duration + hold seconds
    now = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, now, 0, speed, returnDuration) for returnDuration + 0.3 seconds
    do FollowLaneBehavior(target_speed=speed)
''', ("SlideOffset",)),
    "SwerveAndBack": ('''\
behavior SwerveAndBack(speed, delay, depth, duration):
    # a quick sideways move of `depth` m (left positive) inside the lane, then straight back to its centre
    do FollowLaneBehavior(target_speed=speed) for delay seconds
    homeLine = self.laneSection.centerline
    do SlideOffset(homeLine, 0, depth, speed, duration) for duration seconds
    now = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, now, 0, speed, duration) for duration + 0.3 seconds
    do FollowLaneBehavior(target_speed=speed)
''', ("SlideOffset",)),
    "SwerveWhenBlocked": ('''
behavior SwerveWhenBlocked(speed, depth, duration):
    # keep the lane until something blocks the path (at the latest after 4 s), swerve `depth` m
    # (left positive) inside the lane and back, then keep the lane braking for anything in the path
    do FollowLaneBehavior(target_speed=speed) for 0.4 seconds
    do FollowLaneBehavior(target_speed=speed) until pathBlocked(self, 10) or simulation().currentTime * simulation().timestep > 4
    homeLine = self.laneSection.centerline
    do SlideOffset(homeLine, 0, depth, speed, duration) for duration seconds
    now = homeLine.signedDistanceTo(self.position)
    do SlideOffset(homeLine, now, 0, speed, duration) for duration + 0.3 seconds
    do CautiousCruise(speed)
''', ("SlideOffset", "pathBlocked", "CautiousCruise")),
    "MergeFromRamp": ('''\
behavior MergeFromRamp(speed, accelLane, delay, duration):
    # drive down the ramp, then leave the acceleration lane for the main carriageway
    do FollowLaneBehavior(target_speed=speed) until self.lane is accelLane
    do FollowLaneBehavior(target_speed=speed) for delay seconds
    do ChangeLanes(1, speed, duration)
''', ("ChangeLanes",)),
    "BackUp": ('''
behavior BackUp(backUp):
    # reverse straight back `backUp` m, then stand
    start = self.position
    take SetReverseAction(True)
    while (distance from self to start) < backUp:
        take SetThrottleAction(0.35), SetBrakeAction(0), SetSteerAction(0)
    while self.speed > 0.3:
        take SetThrottleAction(0), SetBrakeAction(1)
    take SetReverseAction(False)
''', ()),
    "SteerOntoLine": ('''
behavior SteerOntoLine(line, speed, duration):
    # from standing beside `line`, steer onto it with a gentle heading (at most 0.3 rad off the start heading)
    # while speeding up to `speed`; the stock lane-keeping controller oversteers from standstill and turns the
    # car round. Ends on the line, at the earliest after `duration` s
    elapsed = 0
    reference = self.heading
    while elapsed < duration + 2 and (abs(line.signedDistanceTo(self.position)) > 0.3 or elapsed < duration):
        elapsed += simulation().timestep
        offset = line.signedDistanceTo(self.position)
        relative = self.heading - reference
        while relative > 180 deg:
            relative -= 360 deg
        while relative < -180 deg:
            relative += 360 deg
        wanted = max(-0.3, min(0.3, -0.25 * offset))
        steer = max(-0.3, min(0.3, -1.5 * (wanted - relative)))
        throttle = 0.5 if self.speed < speed else 0
        take SetThrottleAction(throttle), SetBrakeAction(0), SetSteerAction(steer)
''', ()),
    "PullOutWhenNear": ('''
behavior PullOutWhenNear(line, fromOffset, speed, trigger, backUp, duration):
    # stand at the kerb `fromOffset` m beside `line` (left positive) until the ego is within `trigger` m
    # (a negative trigger: wait -trigger seconds), back up `backUp` m if asked, then steer into the lane
    if trigger < 0:
        do HoldStill() for -trigger seconds
    else:
        do HoldStill() for 0.4 seconds
        do HoldStill() until (distance from self to ego) < trigger
    if backUp > 0:
        do BackUp(backUp)
    do SteerOntoLine(line, speed, duration)
    do FollowLaneBehavior(target_speed=speed)
''', ("HoldStill", "BackUp", "SteerOntoLine")),
    "BackUpThenPullOutInto": ('''
behavior BackUpThenPullOutInto(line, speed, backUp, other, trigger, duration):
    # parked at the kerb beside `line`: back up `backUp` m, wait until `other` (coming along the lane from
    # behind) is within `trigger` m, then steer into the lane, into its path
    do HoldStill() for 0.4 seconds
    do BackUp(backUp)
    do HoldStill() until (distance from self to other) < trigger
    do SteerOntoLine(line, speed, duration)
    do FollowLaneBehavior(target_speed=speed)
''', ("HoldStill", "BackUp", "SteerOntoLine")),
    "UTurnLater": ('''
behavior UTurnLater(speed, after, turnSpeed, steer):
    # drive on for `after` seconds, slow to turnSpeed and turn round to the left (steer 0..1) until
    # the heading has changed by about 170 degrees, then follow the lane it ends up in
    do FollowLaneBehavior(target_speed=speed) for after seconds
    while self.speed > turnSpeed + 0.5:
        take SetThrottleAction(0), SetBrakeAction(0.8)
    start = self.heading
    turned = 0
    last = self.heading
    while turned < 170 deg:
        step = self.heading - last
        if step > 180 deg:
            step -= 360 deg
        if step < -180 deg:
            step += 360 deg
        turned += abs(step)
        last = self.heading
        throttle = 0.25 if self.speed < turnSpeed else 0
        take SetThrottleAction(throttle), SetBrakeAction(0), SetSteerAction(-steer)
    take SetSteerAction(0)
    do FollowLaneBehavior(target_speed=speed)
''', ()),
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


def _closure(names: Iterable[str]) -> List[str]:
    """Block names with everything they need, dependencies first, each once."""
    ordered: List[str] = []

    def visit(name: str) -> None:
        if name in ordered:
            return
        deps = BEHAVIORS[name][1] if name in BEHAVIORS else ()
        for dep in deps:
            visit(dep)
        ordered.append(name)

    for name in names:
        visit(name)
    return ordered


def helper_text(names: Iterable[str]) -> str:
    """Scenic text of the helper functions among ``names`` (and their dependencies)."""
    return "\n".join(HELPERS[n] for n in _closure(names) if n in HELPERS)


def behavior_text(names: Iterable[str]) -> str:
    """Scenic text of the behaviours ``names`` with every block they need."""
    blocks = _closure(names)
    return "\n".join([HELPERS[n] for n in blocks if n in HELPERS] + [BEHAVIORS[n][0] for n in blocks if n in BEHAVIORS])


def context_hash() -> str:
    """Hash of every block: changes whenever the generator's building blocks change."""
    digest = hashlib.sha256()
    for table in (HELPERS, {k: v[0] for k, v in BEHAVIORS.items()}):
        for name in sorted(table):
            digest.update(name.encode())
            digest.update(table[name].encode())
    return digest.hexdigest()[:16]
