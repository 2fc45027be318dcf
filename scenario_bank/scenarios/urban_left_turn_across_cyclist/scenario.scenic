"""Turning across a cyclist at a crossroads: the ego turns left at a four-way junction while an oncoming
cyclist rides straight through it and crosses the ego's turning path just ahead of it."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(6, 9)
param ego_distance = Range(25, 40)
param cyclist_speed = Range(4, 6)
param cyclist_lead_time = Range(1.6, 2.2)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoRoute, lead):
    # ride toward the point where the two ways through the junction cross, adapting speed all the way
    # to it so as to get there `lead` seconds before the ego does at its current speed (the ego's time is
    # read every step from its distance along its way and its speed, so an ego that slows down gets a
    # cyclist that slows down too, and one that speeds up a cyclist that hurries), then ride on through
    # at a steady speed
    entry = route[0].centerline.end
    egoEntry = egoRoute[0].centerline.end
    own = route[1].centerline
    egoTurn = egoRoute[1].centerline
    samples = [0.25 * k for k in range(int(4 * own.length) + 1)]
    offsets = [egoTurn.distanceTo(own.pointAlongBy(d)) for d in samples]
    inside = samples[offsets.index(min(offsets))]
    crossing = own.pointAlongBy(inside)
    ownEnd = own.pointAlongBy(own.length)
    egoSamples = [0.25 * k for k in range(int(4 * egoTurn.length) + 1)]
    egoOffsets = [(distance from egoTurn.pointAlongBy(d) to crossing) for d in egoSamples]
    egoInside = egoSamples[egoOffsets.index(min(egoOffsets))]
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    egoEntered = False
    onTurn = False
    toCrossing = (distance from self to entry) + inside
    while toCrossing > 0.5:
        onTurn = onTurn or (distance from self to entry) < 0.5 or self.position in network.intersectionRegion
        line = own if onTurn else route[0].centerline
        toCrossing = (distance from self to ownEnd) - (own.length - inside) if onTurn else (distance from self to entry) + inside
        egoEntered = egoEntered or (distance from ego to egoEntry) < 2 or ego.position in network.intersectionRegion
        egoLeft = (distance from ego to crossing) if egoEntered else (distance from ego to egoEntry) + egoInside
        wanted = toCrossing / max(egoLeft / max(ego.speed, 1) - lead, 0.3)
        wanted = min(1.6 * speed, max(1.5, wanted))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior TurnLeft(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; the ego turns left across the oncoming lane, from which the
# cyclist goes straight
turnPairs = [(m, c) for junction in network.intersections for m in junction.maneuvers
             if m.type is ManeuverType.LEFT_TURN
             for c in m.conflictingManeuvers
             if c.type is ManeuverType.STRAIGHT and c.endLane.road is m.startLane.road]
turnPair = Uniform(*turnPairs)
egoManeuver = turnPair[0]
cyclistManeuver = turnPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
cyclistRoute = [cyclistManeuver.startLane, cyclistManeuver.connectingLane, cyclistManeuver.endLane]
# the cyclist starts about where it would reach the ego's turning path cyclist_lead_time seconds
# before the ego (estimating where the paths cross from the lengths of the two ways through the junction;
# SyncArrival finds the crossing itself and adapts the cyclist's speed on the way)
egoTime = (globalParameters.ego_distance + 0.45 * egoManeuver.connectingLane.centerline.length) / globalParameters.ego_speed
cyclistDistance = max(5, globalParameters.cyclist_speed * (egoTime - globalParameters.cyclist_lead_time)
                      - 0.6 * cyclistManeuver.connectingLane.centerline.length)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior TurnLeft(globalParameters.ego_speed, egoRoute)
cyclist = new Bicycle at cyclistManeuver.startLane.centerline.pointAlongBy(-(2 + cyclistDistance)),
    with name "cyclist",
    with speed globalParameters.cyclist_speed,
    with behavior SyncArrival(globalParameters.cyclist_speed, cyclistRoute, egoRoute,
                              globalParameters.cyclist_lead_time)
