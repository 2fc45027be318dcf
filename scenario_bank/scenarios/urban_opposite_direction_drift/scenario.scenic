"""Opposite-direction drift on an urban street: an oncoming car drifts across the centre line into
the ego's lane and then steers back into its own lane."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'WetCloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param oncoming_speed = Range(9, 13)
param oncoming_distance = Range(100, 130)
param drift_trigger = Range(65, 85)
param drift_depth = Range(2.3, 3.3)
param drift_duration = Range(2.0, 3.0)
param return_trigger = Range(32, 42)
param return_duration = Range(2.0, 3.0)

# 2. Adversarial behaviours
behavior SlideSideways(line, fromOffset, toOffset, speed, duration):
    # follow `line` at a lateral offset (metres, left positive) that slides smoothly from
    # fromOffset to toOffset within `duration` seconds, then stays there
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    i = 0
    while True:
        i = min(i + 1, steps)
        u = i / steps
        reference = fromOffset + (toOffset - fromOffset) * u * u * (3 - 2 * u)
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior DriftAcrossCentre(speed, driftTrigger, depth, driftTime, returnTrigger, returnTime):
    # drift over the centre line into the ego's lane once it is near, then steer back before reaching it
    do FollowLaneBehavior(target_speed=speed) until (distance from self to ego) < driftTrigger
    homeLine = self.laneSection.centerline
    do SlideSideways(homeLine, 0, depth, speed, driftTime) until (distance from self to ego) < returnTrigger
    offset = homeLine.signedDistanceTo(self.position)
    do SlideSideways(homeLine, offset, 0, speed, returnTime) for returnTime + 1 seconds
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a two-way urban street, one lane per direction (the ego's and the oncoming one)
lanePairs = [(lane, other) for lane in network.lanes for other in network.lanes if other is not lane]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
oncomingLane = lanePair[1]
egoS = Range(60, 400)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
# both lanes are 600 m long: a negative distance counts back from the oncoming lane's end
oncoming = new Car at oncomingLane.centerline.pointAlongBy(-(egoS + globalParameters.oncoming_distance)),
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior DriftAcrossCentre(globalParameters.oncoming_speed, globalParameters.drift_trigger,
                                    globalParameters.drift_depth, globalParameters.drift_duration,
                                    globalParameters.return_trigger, globalParameters.return_duration)
