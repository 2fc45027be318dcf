"""Left turn across an oncoming car at a T-junction: the ego turns left from the main road into the
side road while an oncoming car goes straight through the junction."""

# 1. Map and global parameters
param map = 'urban_t_junction'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param ego_distance = Range(20, 40)
param oncoming_speed = Range(8, 12)
param arrival_offset = Range(-0.5, 1.0)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoEntry, offset):
    # approach the junction adapting speed so as to enter it `offset` seconds after the ego does
    # (at the ego's current speed), then drive through at a steady speed
    entry = route[0].centerline.end
    line = route[0].centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    egoEntered = False
    while (distance from self to entry) > 3:
        egoEntered = egoEntered or (distance from ego to egoEntry) < 3 or ego.position in network.intersectionRegion
        egoTime = 0 if egoEntered else (distance from ego to egoEntry) / max(ego.speed, 1)
        wanted = (distance from self to entry) / max(egoTime + offset, 0.5)
        wanted = min(1.4 * speed, max(3, wanted))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior DriveRoute(speed, route, turnSpeed):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=turnSpeed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a T-junction; the ego's left turn and the oncoming straight movement it crosses
turnPairs = [(m, c) for junction in network.intersections for m in junction.maneuvers
             if m.type is ManeuverType.LEFT_TURN
             for c in m.conflictingManeuvers
             if c.type is ManeuverType.STRAIGHT and c.endLane.road is m.startLane.road]
turnPair = Uniform(*turnPairs)
egoManeuver = turnPair[0]
oncomingManeuver = turnPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
oncomingRoute = [oncomingManeuver.startLane, oncomingManeuver.connectingLane, oncomingManeuver.endLane]
egoEntry = egoManeuver.startLane.centerline.end
# the oncoming car starts where it would reach the junction about when the ego does
egoTime = globalParameters.ego_distance / globalParameters.ego_speed
oncomingDistance = globalParameters.oncoming_speed * (egoTime + globalParameters.arrival_offset)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute, globalParameters.ego_speed)
oncoming = new Car at oncomingManeuver.startLane.centerline.pointAlongBy(-(1 + oncomingDistance)),
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior SyncArrival(globalParameters.oncoming_speed, oncomingRoute, egoEntry,
                              globalParameters.arrival_offset)
