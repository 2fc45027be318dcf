"""Straight crossing paths at a crossroads: while the ego goes straight through the junction, a car
from the side road goes straight across it and crosses the ego's path."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param ego_distance = Range(25, 45)
param crosser_speed = Range(8, 12)
param crosser_lead_time = Range(-0.3, 1.2)

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

behavior DriveRoute(speed, route):
    # keep speed through the junction (no slowing down for it)
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; two straight movements that cross each other
crossPairs = [(m, c) for junction in network.intersections for m in junction.maneuvers
              if m.type is ManeuverType.STRAIGHT
              for c in m.conflictingManeuvers if c.type is ManeuverType.STRAIGHT]
crossPair = Uniform(*crossPairs)
egoManeuver = crossPair[0]
crosserManeuver = crossPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
crosserRoute = [crosserManeuver.startLane, crosserManeuver.connectingLane, crosserManeuver.endLane]
egoEntry = egoManeuver.startLane.centerline.end
# the crosser starts where it would enter the junction crosser_lead_time seconds before the ego
egoTime = globalParameters.ego_distance / globalParameters.ego_speed
crosserDistance = globalParameters.crosser_speed * (egoTime - globalParameters.crosser_lead_time)

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
crosser = new Car at crosserManeuver.startLane.centerline.pointAlongBy(-(1 + crosserDistance)),
    with name "crosser",
    with speed globalParameters.crosser_speed,
    with behavior SyncArrival(globalParameters.crosser_speed, crosserRoute, egoEntry,
                              -globalParameters.crosser_lead_time)
