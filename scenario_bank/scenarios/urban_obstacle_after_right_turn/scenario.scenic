"""Object after a turn at a crossroads: the ego turns right through the junction and, just past the
turn, a lost load lies in the lane it turns into."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param ego_distance = Range(15, 35)
param obstacle_position = Range(14, 22)
param obstacle_width = Range(1.2, 2.2)
param obstacle_length = Range(0.8, 2.0)

# 2. Adversarial behaviours
# (the obstacle lies still: the point of this scenario is an object the ego meets right after its
# turn, hidden from it by the corner until it has turned)
behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=0.7 * speed)
    do FollowLaneBehavior(target_speed=speed)

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
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
obstacle = new Obstacle at egoManeuver.endLane.centerline.pointAlongBy(globalParameters.obstacle_position),
    with name "obstacle",
    with width globalParameters.obstacle_width,
    with length globalParameters.obstacle_length
