"""Scenic behaviours of vehicles on straight roads: cruise, brake, change lanes, cut in, overtake, drift,
swerve, merge, back up, pull out, turn round. Name -> (Scenic text, names of the blocks it needs)."""

from __future__ import annotations

from typing import Dict, Tuple

__all__ = ["LANE_BEHAVIORS"]

LANE_BEHAVIORS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
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
}
