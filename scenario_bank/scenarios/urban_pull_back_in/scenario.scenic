"""Pull back in on an urban highway: a faster car overtakes the ego and cuts back in ahead of it."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(14, 18)
param overtaker_extra_speed = Range(5, 8)
param start_gap = Range(30, 40)
param pull_out_gap = Range(22, 27)
param return_gap = Range(5, 10)
param slow_down_to = Range(10, 14)
param lane_change_duration = Range(1.8, 2.6)

# 2. Adversarial behaviours
behavior SlideToLane(section, extraSpeed, duration):
    # change lanes by tracking a reference that slides smoothly from the current lateral offset
    # to the centre of the target lane section within `duration` seconds, `extraSpeed` faster than the ego
    line = section.centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    startOffset = line.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        throttle = lonControl.run_step(ego.speed + extraSpeed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior PaceEgoUntil(extraSpeed, aheadOfEgo):
    # follow the lane `extraSpeed` faster than the ego, whatever its speed, until `aheadOfEgo` metres
    # ahead of it (negative: behind it)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while (distance past ego of self) <= aheadOfEgo:
        throttle = lonControl.run_step(ego.speed + extraSpeed - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior OvertakeAndPullBackIn(extraSpeed, pullOutGap, returnGap, slowSpeed, duration):
    # triggers on the ego: close in behind it, pull out to the left when `pullOutGap` metres
    # behind, pass at `extraSpeed` above the ego's current speed (an ego that rushes is still passed),
    # pull back in `returnGap` metres ahead (distance past ego of self: how far self is ahead of the ego)
    do PaceEgoUntil(extraSpeed, -pullOutGap)
    do SlideToLane(self.laneSection.laneToLeft, extraSpeed, duration)
    do PaceEgoUntil(extraSpeed, returnGap + 5)
    do SlideToLane(self.laneSection.laneToRight, extraSpeed / 2, duration)
    do FollowLaneBehavior(target_speed=slowSpeed)

# 3. Road geometry: a straight multi-lane road; the ego keeps a lane that has a lane to its left
egoLane = Uniform(*filter(lambda l: l.sections[0]._laneToLeft is not None, network.lanes))

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(Range(100, 1100)),
    with speed globalParameters.ego_speed
overtaker = new Car following roadDirection from ego for -globalParameters.start_gap,
    with name "overtaker",
    with speed globalParameters.ego_speed + globalParameters.overtaker_extra_speed,
    with behavior OvertakeAndPullBackIn(globalParameters.overtaker_extra_speed, globalParameters.pull_out_gap,
                                        globalParameters.return_gap, globalParameters.slow_down_to,
                                        globalParameters.lane_change_duration)
traffic = new Car following roadDirection from ego for Range(40, 65),
    with speed Range(16, 19), with behavior FollowLaneBehavior(target_speed=Range(16, 19))
