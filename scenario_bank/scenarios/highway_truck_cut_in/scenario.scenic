"""Truck cut-in on a highway: a slower truck in the lane to the ego's right pulls into the ego's
lane shortly before the ego reaches it."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'WetCloudyNoon')
model scenic.domains.driving.model

param ego_speed = Range(22, 26)
param truck_speed = Range(16, 20)
param truck_gap = Range(45, 70)
param cut_in_trigger = Range(28, 42)
param lane_change_duration = Range(3.0, 4.5)

# 2. Adversarial behaviours
behavior SlideToLane(section, speed, duration):
    # change lanes by tracking a reference that slides smoothly from the current lateral offset
    # to the centre of the target lane section within `duration` seconds
    line = section.centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    startOffset = line.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior StaySlowerThanEgo(speed, trigger, duration):
    # keep right at `speed`, or slower when the ego hangs back, so that the ego closes in, until it is
    # within `trigger` metres behind (at most 2 s of its speed) or would reach the truck before a lane
    # change could end (distance past ego of self: how far self is ahead of the ego)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    line = self.lane.centerline
    pastSteer = 0
    while (distance past ego of self) >= max(min(trigger, 2 * ego.speed), (ego.speed - self.speed) * (duration + 1)):
        wanted = max(5, min(speed, ego.speed - 5))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior PullOutInFrontOf(speed, trigger, duration):
    # keep right until the faster ego is within `trigger` metres behind, then move into its lane at the
    # speed it has then
    do StaySlowerThanEgo(speed, trigger, duration)
    cutSpeed = max(5, min(speed, self.speed))
    do SlideToLane(self.laneSection.laneToLeft, cutSpeed, duration)
    do FollowLaneBehavior(target_speed=cutSpeed)

# 3. Road geometry: a straight multi-lane highway; the ego's lane and the lane to its right
lanePairs = [(lane, lane.sections[0]._laneToRight.lane) for lane in network.lanes
             if lane.sections[0]._laneToRight is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
truckLane = lanePair[1]
egoS = Range(50, 1100)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
truck = new Truck at truckLane.centerline.pointAlongBy(egoS + globalParameters.truck_gap),
    with name "truck",
    with speed globalParameters.truck_speed,
    with behavior PullOutInFrontOf(globalParameters.truck_speed, globalParameters.cut_in_trigger,
                                   globalParameters.lane_change_duration)
traffic = new Car at truckLane.centerline.pointAlongBy(egoS + globalParameters.truck_gap + Range(25, 50)),
    with speed globalParameters.truck_speed + Range(0, 3),
    with behavior FollowLaneBehavior(target_speed=globalParameters.truck_speed + 2)
