"""Simultaneous merge into the middle lane: the ego moves from the left lane to the middle lane
while a car on the right lane moves into the middle lane at about the same time."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(20, 26)
param other_speed_delta = Range(-1.5, 1.5)
param ego_change_after = Range(1.0, 2.5)
param other_change_offset = Range(-0.6, 0.6)
param other_offset = Range(-6, 6)
param lane_change_duration = Range(2.0, 3.0)

# 2. Adversarial behaviours
behavior ChangeLaneAfter(speed, after, toLeft):
    # the ego's own manoeuvre: keep the lane for `after` seconds, then move one lane over
    do FollowLaneBehavior(target_speed=speed) for after seconds
    if toLeft:
        do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToLeft, target_speed=speed)
    else:
        do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToRight, target_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior MergeBesideEgo(egoLine, offset, speedDelta, patience, duration):
    # triggers on the ego: hold `offset` metres ahead of it (negative: behind) two lanes to its right,
    # whatever its speed, and once in that slot move into the middle lane as soon as the ego starts to
    # leave its lane (or, for an ego that keeps its lane, after pacing it for `patience` seconds); the
    # lane change keeps pace with the ego, so the two meet in the middle lane
    # (distance past self of ego: how far the ego is ahead of self)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    line = self.lane.centerline
    pastSteer = 0
    paced = 0
    while True:
        ahead = -(distance past self of ego)
        inSlot = abs(offset - ahead) < 2
        egoLeaving = abs(egoLine.signedDistanceTo(ego.position)) > 0.5
        if inSlot and (egoLeaving or paced >= patience):
            break
        target = min(max(ego.speed + 0.6 * (offset - ahead), 0), ego.speed + 6)
        throttle = lonControl.run_step(target - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
        if inSlot:
            paced += simulation().timestep
    middle = self.laneSection.laneToLeft.centerline
    startOffset = middle.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        throttle = lonControl.run_step(ego.speed + speedDelta - self.speed)
        steer = latControl.run_step(middle.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowLaneBehavior(target_speed=max(ego.speed + speedDelta, 5))

# 3. Road geometry: three adjacent lanes of a straight highway (left, middle, right)
def rightOf(lane):
    section = lane.sections[0]._laneToRight
    return None if section is None else section.lane
laneTriples = [(lane, rightOf(lane), rightOf(rightOf(lane))) for lane in network.lanes
               if rightOf(lane) is not None and rightOf(rightOf(lane)) is not None]
laneTriple = Uniform(*laneTriples)
leftLane = laneTriple[0]
rightLane = laneTriple[2]
egoS = Range(50, 1200)

# 4. Spawn positions
ego = new Car at leftLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior ChangeLaneAfter(globalParameters.ego_speed, globalParameters.ego_change_after, False)
other = new Car at rightLane.centerline.pointAlongBy(egoS + globalParameters.other_offset),
    with name "other",
    with speed globalParameters.ego_speed + globalParameters.other_speed_delta,
    with behavior MergeBesideEgo(leftLane.centerline, globalParameters.other_offset,
                                 globalParameters.other_speed_delta,
                                 globalParameters.ego_change_after + globalParameters.other_change_offset,
                                 globalParameters.lane_change_duration)
