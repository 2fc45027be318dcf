"""Left turn at an urban intersection with oncoming cars going straight."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(6, 10)
param oncoming_speed = Range(8, 13)
param arrival_offset = Range(-0.5, 0.8)
param follower_delay = Range(1.5, 2.5)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoRoute, offset):
    # approach the junction adapting speed so as to enter it `offset` seconds after the ego does (at the
    # ego's current speed); then, in the junction, hold back (down to 3 m/s) while the ego is more than
    # 2.5 s short of the crossing point of the two paths (its distance over its speed, taken as at least
    # 5 m/s): an ego that slows down or stops in the junction still has the car cross just ahead of it;
    # past the crossing point drive on at a steady speed
    egoEntry = egoRoute[0].centerline.end
    egoLine = egoRoute[1].centerline
    crossLine = route[1].centerline
    conflict = crossLine.pointAlongBy(min(range(int(crossLine.length) + 1),
                                          key=lambda d: egoLine.distanceTo(crossLine.pointAlongBy(d))))
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    egoEntered = False
    line = route[0].centerline
    while (distance past line.end of self) < 0:
        egoEntered = egoEntered or (distance from ego to egoEntry) < 3 or ego.position in network.intersectionRegion
        egoTime = 0 if egoEntered else (distance from ego to egoEntry) / max(ego.speed, 1)
        wanted = (distance from self to line.end) / max(egoTime + offset, 0.5)
        wanted = min(1.4 * speed, max(3, wanted))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    line = crossLine
    while (distance past line.end of self) < 0 and (distance past conflict of self) < 0:
        egoGap = (distance from ego to conflict) / max(ego.speed, 5)
        wanted = speed if egoGap <= 2.5 else max(3, min(speed, (distance from self to conflict) / (egoGap - 2)))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route[1:], turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)


behavior TurnLeft(speed, trajectory):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=trajectory)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way intersection of two-way roads
turnPairs = [(m, c) for junction in network.intersections for m in junction.maneuvers
             if m.type is ManeuverType.LEFT_TURN
             for c in m.conflictingManeuvers
             if c.type is ManeuverType.STRAIGHT and c.endLane.road is m.startLane.road]
turnPair = Uniform(*turnPairs)
egoManeuver = turnPair[0]
oncomingManeuver = turnPair[1]
intersection = egoManeuver.intersection
egoStart = egoManeuver.startLane
egoRoute = [egoStart, egoManeuver.connectingLane, egoManeuver.endLane]
oncomingStart = oncomingManeuver.startLane
oncomingRoute = [oncomingStart, oncomingManeuver.connectingLane, oncomingManeuver.endLane]
egoEntry = egoStart.centerline.end

# 4. Spawn positions
ego = new Car following roadDirection from egoStart.centerline.end for -Range(12, 35),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior TurnLeft(globalParameters.ego_speed, egoRoute)
oncoming = new Car following roadDirection from oncomingStart.centerline.end for -Range(15, 50),
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior SyncArrival(globalParameters.oncoming_speed, oncomingRoute, egoRoute,
                              globalParameters.arrival_offset)
follower = new Car following roadDirection from oncoming for Range(-25, -12),
    with name "follower",
    with speed globalParameters.oncoming_speed,
    with behavior SyncArrival(globalParameters.oncoming_speed, oncomingRoute, egoRoute,
                              globalParameters.arrival_offset + globalParameters.follower_delay)
