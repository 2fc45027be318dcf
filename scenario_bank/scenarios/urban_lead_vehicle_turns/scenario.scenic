"""Lead vehicle turning at a crossroads: the car driving just ahead of the ego in its lane slows down
sharply and turns right at the junction while the ego goes straight on behind it."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(9, 12)
param ego_distance = Range(60, 80)
param time_gap = Range(1.8, 2.5)
param brake_distance = Range(5, 9)
param brake_strength = Range(0.6, 0.9)
param turn_speed = Range(4, 5.5)

# 2. Adversarial behaviours
behavior LeadEgo(line, timeGap, floor):
    # drive ahead of the ego keeping about `timeGap` seconds of its speed between them (an ego that
    # hangs back or rushes keeps the same gap to a lead that adapts), never slower than `floor`
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while True:
        gap = (distance past ego of self) - 5
        wanted = max(floor, ego.speed - 0.5 * (gap - timeGap * max(ego.speed, 3)))
        throttle = lonControl.run_step(min(wanted, 16) - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior SlowDownAndTurn(route, timeGap, brakeDistance, strength, turnSpeed):
    # lead the ego toward the junction (at least 4 m/s faster than the turn, so that its braking is
    # sharp even behind an ego that slows down), brake hard `brakeDistance` metres before it, then turn
    entry = route[0].centerline.end
    do LeadEgo(route[0].centerline, timeGap, turnSpeed + 4) until (distance from self to entry) < brakeDistance
    while self.speed > turnSpeed:
        take SetThrottleAction(0), SetBrakeAction(strength)
    do FollowTrajectoryBehavior(target_speed=turnSpeed, trajectory=route, turn_speed=turnSpeed)
    do FollowLaneBehavior(target_speed=8)

behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; from one incoming lane the ego goes straight and the lead
# turns right
pairs = [(m, t) for junction in network.intersections for m in junction.maneuvers
         if m.type is ManeuverType.STRAIGHT
         for t in junction.maneuvers
         if t.startLane is m.startLane and t.type is ManeuverType.RIGHT_TURN]
pair = Uniform(*pairs)
egoManeuver = pair[0]
leadManeuver = pair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
leadRoute = [leadManeuver.startLane, leadManeuver.connectingLane, leadManeuver.endLane]
leadDistance = globalParameters.ego_distance - 5 - globalParameters.time_gap * globalParameters.ego_speed

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
lead = new Car at leadManeuver.startLane.centerline.pointAlongBy(-leadDistance),
    with name "lead",
    with speed globalParameters.ego_speed,
    with behavior SlowDownAndTurn(leadRoute, globalParameters.time_gap, globalParameters.brake_distance,
                                  globalParameters.brake_strength, globalParameters.turn_speed)
