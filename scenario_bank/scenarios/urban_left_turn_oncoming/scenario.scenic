"""Left turn at an urban intersection with oncoming cars going straight."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(6, 10)
param oncoming_speed = Range(8, 13)
param arrival_offset = Range(-0.7, 0.0)
param follower_delay = Range(1.5, 2.5)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoRoute, offset):
    # time the car's clearing of the ego's turn for `offset` seconds after the ego reaches it (negative: the
    # car's rear leaves the stretch of its lane that the turning ego sweeps just before the ego's front gets
    # there). The ego's time is its remaining distance along its own route over its current speed (at least
    # 1 m/s). The car adapts all the way in: it holds back (down to 2 m/s, to a stop before the junction) for
    # an ego that hangs back or stops, speeds up (up to 2.2 times its speed) for one that rushes; once clear
    # it drives on at a steady speed
    egoLine = egoRoute[1].centerline
    crossLine = route[1].centerline
    swept = [d for d in range(int(crossLine.length) + 1) if egoLine.distanceTo(crossLine.pointAlongBy(d)) < 2.5]
    clearAt = min(max(swept) + 1, crossLine.length)
    clear = crossLine.pointAlongBy(clearAt)
    egoAt = max(0, min(d for d in range(int(egoLine.length) + 1)
                       if crossLine.distanceTo(egoLine.pointAlongBy(d)) < 2.5) - 2)
    egoEntry = egoRoute[0].centerline.end
    egoReach = egoLine.pointAlongBy(egoAt)
    entry = route[0].centerline.end
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    egoEntered = False
    entered = False
    while (distance past clear of self) < 0:
        egoEntered = egoEntered or (distance from ego to egoEntry) < 3 or ego.position in network.intersectionRegion
        entered = entered or (distance past entry of self) >= 0
        egoLeft = (distance from ego to egoReach) if egoEntered else (distance from ego to egoEntry) + egoAt
        left = (distance from self to clear) if entered else (distance from self to entry) + clearAt
        egoTime = egoLeft / max(ego.speed, 1)
        wanted = left / max(egoTime + offset, 0.3)
        wanted = min(2.2 * speed, max(2 if entered else 0, wanted))
        line = crossLine if entered else route[0].centerline
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route[1:], turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)


behavior GiveWay(speed, route, egoRoute, lead, delay):
    # the second oncoming car: keeps `delay` seconds behind the first and gives way to the turning ego,
    # stopping short of the junction while the ego is about to enter it or is inside it
    entry = route[0].centerline.end
    egoEntry = egoRoute[0].centerline.end
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    line = route[0].centerline
    while (distance past entry of self) < 0:
        wanted = min(1.2 * speed, max(0, ((distance from self to lead) - 5) / delay))
        if ego.position in network.intersectionRegion or (distance from ego to egoEntry) < 8:
            wanted = min(wanted, max(0, (distance from self to entry) - 3) / 1.5)
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
# the oncoming car starts about as far from the junction, in time at its speed, as the ego: a little nearer
# (it has farther to go in the junction, past the ego's turn), so that it holds back rather than catches up
egoBack = Range(12, 35)
oncomingBack = max(8, min(50, Range(0.7, 0.95) * egoBack * globalParameters.oncoming_speed / globalParameters.ego_speed - 8))
ego = new Car following roadDirection from egoStart.centerline.end for -egoBack,
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior TurnLeft(globalParameters.ego_speed, egoRoute)
oncoming = new Car following roadDirection from oncomingStart.centerline.end for -oncomingBack,
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior SyncArrival(globalParameters.oncoming_speed, oncomingRoute, egoRoute,
                              globalParameters.arrival_offset)
follower = new Car following roadDirection from oncoming for Range(-25, -12),
    with name "follower",
    with speed globalParameters.oncoming_speed,
    with behavior GiveWay(globalParameters.oncoming_speed, oncomingRoute, egoRoute, oncoming,
                          globalParameters.follower_delay)
