"""Drifting in the same direction on a highway: a car in the lane next to the ego, a little ahead of it,
drifts over the lane line into the ego's lane without changing lanes, then steers back into its own lane."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'HardRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(20, 27)
param start_ahead = Range(25, 40)
param slower_by = Range(2, 4)
param drift_gap = Range(11, 17)
param drift_depth = Range(1.95, 2.25)
param drift_duration = Range(1.5, 2.0)
param drift_hold = Range(2.0, 3.0)
param return_duration = Range(1.5, 2.5)

# 2. Adversarial behaviours
behavior SlideSideways(line, fromOffset, toOffset, duration):
    # follow `line` at a lateral offset (metres, left positive) that slides smoothly from fromOffset
    # to toOffset within `duration` seconds, then stays there; keeps the speed it has when it starts
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    speed = self.speed
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

behavior LetEgoCloseIn(line, slowerBy, gap):
    # drive in its own lane a little slower than the ego (whatever the ego's speed), so the ego
    # closes in from behind, until it is only `gap` metres ahead of the ego
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while (distance past ego of self) > gap:
        wanted = max(3, ego.speed - slowerBy)
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior DriftIntoEgoLane(slowerBy, gap, depth, driftTime, hold, returnTime):
    # when just ahead of the ego, drift `depth` metres toward the ego's lane (the centre crosses the
    # lane line, never reaching the ego lane's centre), hold it, then steer back to its own lane
    home = self.laneSection.centerline
    do LetEgoCloseIn(home, slowerBy, gap)
    side = 1 if home.signedDistanceTo(ego.position) > 0 else -1
    do SlideSideways(home, 0, side * depth, driftTime) for driftTime + hold seconds
    offset = home.signedDistanceTo(self.position)
    do SlideSideways(home, offset, 0, returnTime) for returnTime + 1 seconds
    do FollowLaneBehavior(target_speed=self.speed)

# 3. Road geometry: a straight four-lane one-way highway; the ego's lane and one next to it
lanePairs = [(lane, side.lane) for lane in network.lanes
             for side in (lane.sections[0]._laneToLeft, lane.sections[0]._laneToRight) if side is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
drifterLane = lanePair[1]
egoS = Range(50, 1000)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
drifter = new Car at drifterLane.centerline.pointAlongBy(egoS + globalParameters.start_ahead),
    with name "drifter",
    with speed globalParameters.ego_speed - globalParameters.slower_by,
    with behavior DriftIntoEgoLane(globalParameters.slower_by, globalParameters.drift_gap,
                                   globalParameters.drift_depth, globalParameters.drift_duration,
                                   globalParameters.drift_hold, globalParameters.return_duration)
