"""Left turn at an urban intersection with oncoming cars going straight."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(6, 10)
param oncoming_speed = Range(8, 13)

# 2. Adversarial behaviours
behavior GoStraightThrough(speed, trajectory):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=trajectory)
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

# 4. Spawn positions
ego = new Car following roadDirection from egoStart.centerline.end for -Range(12, 35),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior TurnLeft(globalParameters.ego_speed, egoRoute)
oncoming = new Car following roadDirection from oncomingStart.centerline.end for -Range(15, 50),
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior GoStraightThrough(globalParameters.oncoming_speed, oncomingRoute)
follower = new Car following roadDirection from oncoming for Range(-25, -12),
    with name "follower",
    with speed globalParameters.oncoming_speed,
    with behavior GoStraightThrough(globalParameters.oncoming_speed, oncomingRoute)
