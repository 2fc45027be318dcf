"""Cyclist crossing at a crossroads: while the ego goes straight through the junction, a cyclist from a
side road rides straight across it and crosses the ego's path just ahead of it."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 11)
param ego_distance = Range(30, 45)
param cyclist_speed = Range(4, 6)
param cyclist_lead_time = Range(0.6, 1.4)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoPath, lead):
    # ride toward the junction adapting speed so as to reach the ego's path (the ego's way through
    # the junction, `egoPath`) `lead` seconds before the ego would reach the cyclist's path at its
    # current speed (an ego that slows down gets a cyclist that waits for it), then ride straight
    # across at a steady speed
    entry = route[0].centerline.end
    line = route[0].centerline
    ownPath = route[1].centerline
    inside = egoPath.distanceTo(entry)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while (distance from self to entry) > 2:
        egoTime = ownPath.distanceTo(ego.position) / max(ego.speed, 1)
        wanted = (distance from self to entry) / max(egoTime - lead - inside / speed, 0.4)
        wanted = min(1.6 * speed, max(1.5, wanted))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; the ego goes straight, the cyclist goes straight across it
crossPairs = [(m, c) for junction in network.intersections for m in junction.maneuvers
              if m.type is ManeuverType.STRAIGHT
              for c in m.conflictingManeuvers if c.type is ManeuverType.STRAIGHT]
crossPair = Uniform(*crossPairs)
egoManeuver = crossPair[0]
cyclistManeuver = crossPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
cyclistRoute = [cyclistManeuver.startLane, cyclistManeuver.connectingLane, cyclistManeuver.endLane]
# the cyclist starts about where it would reach the ego's path cyclist_lead_time seconds before the ego
egoTime = globalParameters.ego_distance / globalParameters.ego_speed
cyclistDistance = max(5, globalParameters.cyclist_speed * (egoTime - globalParameters.cyclist_lead_time) - 8)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
cyclist = new Bicycle at cyclistManeuver.startLane.centerline.pointAlongBy(-(2 + cyclistDistance)),
    with name "cyclist",
    with speed globalParameters.cyclist_speed,
    with behavior SyncArrival(globalParameters.cyclist_speed, cyclistRoute, egoManeuver.connectingLane.centerline,
                              globalParameters.cyclist_lead_time)
