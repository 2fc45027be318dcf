"""Right turn into the ego's path at a crossroads: a car waiting on the side road pulls out as the
ego approaches and turns right into the ego's lane just ahead of it."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'WetCloudyNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 11)
param turner_speed = Range(7, 10)
param turner_wait_position = Range(2, 6)
param trigger_time = Range(3.7, 4.7)
param wait_time = Range(0, 1.5)

# 2. Adversarial behaviours
behavior PullOutWhenEgoNear(speed, route, egoEntry, triggerTime):
    # wait at the give-way line until the ego is about triggerTime seconds from the junction
    while (distance from ego to egoEntry) > triggerTime * max(ego.speed, 1):
        take SetThrottleAction(0), SetBrakeAction(1)
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=0.7 * speed)
    do FollowLaneBehavior(target_speed=speed)

behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; the ego goes straight, the turner turns right from the
# side road into the lane the ego ends in
turnPairs = [(m, r) for junction in network.intersections for m in junction.maneuvers
             if m.type is ManeuverType.STRAIGHT
             for r in junction.maneuvers
             if r.type is ManeuverType.RIGHT_TURN and r.endLane is m.endLane]
turnPair = Uniform(*turnPairs)
egoManeuver = turnPair[0]
turnerManeuver = turnPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
turnerRoute = [turnerManeuver.startLane, turnerManeuver.connectingLane, turnerManeuver.endLane]
egoEntry = egoManeuver.startLane.centerline.end
# the ego starts wait_time seconds (at its speed) beyond the turner's trigger distance
egoDistance = globalParameters.ego_speed * (globalParameters.trigger_time + globalParameters.wait_time)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-egoDistance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
turner = new Car at turnerManeuver.startLane.centerline.pointAlongBy(-globalParameters.turner_wait_position),
    with name "turner",
    with speed 0,
    with behavior PullOutWhenEgoNear(globalParameters.turner_speed, turnerRoute, egoEntry,
                                     globalParameters.trigger_time)
