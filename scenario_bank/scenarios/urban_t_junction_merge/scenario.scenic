"""Merge at a T-junction: a car from the side road turns into the ego's road and merges into the
ego's lane in front of it while the ego goes straight through the junction."""

# 1. Map and global parameters
param map = 'urban_t_junction'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'CloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 11)
param merger_speed = Range(5, 8)
param merger_distance = Range(6, 15)
param merge_lead_time = Range(2.0, 3.0)

# 2. Adversarial behaviours
behavior SyncArrival(speed, route, egoEntry, offset):
    # approach the junction adapting speed so as to enter it `offset` seconds after the ego does
    # (at the ego's current speed; down to a crawl for an ego that slows down), then drive through at a
    # steady speed
    entry = route[0].centerline.end
    line = route[0].centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    egoEntered = False
    while (distance from self to entry) > 3:
        egoEntered = egoEntered or (distance from ego to egoEntry) < 3 or ego.position in network.intersectionRegion
        egoTime = 0 if egoEntered else (distance from ego to egoEntry) / max(ego.speed, 1)
        wanted = (distance from self to entry) / max(egoTime + offset, 0.5)
        wanted = min(1.4 * speed, max(1, wanted))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

behavior DriveRoute(speed, route):
    # drive the route (start lane, junction, end lane) without slowing down in the junction;
    # the merger uses it to turn out of the side road, the ego to go straight on
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a T-junction; the ego goes straight along the main road, the merger turns
# from the side road into the lane the ego ends in
mergePairs = [(m, s) for junction in network.intersections for m in junction.maneuvers
              if m.type is ManeuverType.STRAIGHT
              for s in junction.maneuvers
              if s.type is not ManeuverType.STRAIGHT and s.endLane is m.endLane]
mergePair = Uniform(*mergePairs)
egoManeuver = mergePair[0]
mergerManeuver = mergePair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
mergerRoute = [mergerManeuver.startLane, mergerManeuver.connectingLane, mergerManeuver.endLane]
egoEntry = egoManeuver.startLane.centerline.end
# the ego reaches the junction merge_lead_time seconds after the merger
mergerTime = globalParameters.merger_distance / globalParameters.merger_speed
egoDistance = globalParameters.ego_speed * (mergerTime + globalParameters.merge_lead_time)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-egoDistance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
merger = new Car at mergerManeuver.startLane.centerline.pointAlongBy(-globalParameters.merger_distance),
    with name "merger",
    with speed globalParameters.merger_speed,
    with behavior SyncArrival(globalParameters.merger_speed, mergerRoute, egoEntry,
                              -globalParameters.merge_lead_time)
