"""Object after a turn at a crossroads: the ego turns right through the junction and, just past the
turn, a lost load lies in the lane it turns into."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param ego_distance = Range(15, 35)
param obstacle_position = Range(18, 26)
param obstacle_width = Range(1.2, 2.2)
param obstacle_length = Range(0.8, 2.0)
param stop_margin = Range(2, 4)

# 2. Adversarial behaviours
# (the obstacle lies still: the point of this scenario is an object the ego meets right after its
# turn, hidden from it by the corner until it has turned)
behavior TurnThenStopShort(speed, route, margin):
    # the script's own ego: turn along the route and, in the lane it turns into, brake to stop about
    # `margin` metres short of the obstacle (4 m of the centre-to-centre distance are the two bodies;
    # braking takes about speed^2 / 7 m); it waits to have straightened out unless that leaves no room
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=0.7 * speed) until \
        (self.position in route[2]) and (distance from self to obstacle) < 4 + margin + self.speed * self.speed / 7 \
        and (abs(relative heading of (roadDirection at self.position) from self) < 0.15
             or (distance from self to obstacle) < 3 + self.speed * self.speed / 7)
    latControl = simulation().getLaneFollowingControllers(self)[1]
    pastSteer = 0
    while True:
        # full brake, still steering along the lane (a negative throttle brakes)
        steer = latControl.run_step(route[2].centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(-1, steer, pastSteer)
        pastSteer = steer

# 3. Road geometry: a four-way junction; the ego turns right, and the obstacle lies in the lane it
# turns into, a few metres past the junction (where a car that turned has straightened out)
egoManeuvers = [m for junction in network.intersections for m in junction.maneuvers
                if m.type is ManeuverType.RIGHT_TURN]
egoManeuver = Uniform(*egoManeuvers)
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior TurnThenStopShort(globalParameters.ego_speed, egoRoute, globalParameters.stop_margin)
obstacle = new Obstacle at egoManeuver.endLane.centerline.pointAlongBy(globalParameters.obstacle_position),
    with name "obstacle",
    with width globalParameters.obstacle_width,
    with length globalParameters.obstacle_length
