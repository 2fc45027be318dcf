"""Pedestrian crossing at a crossroads: while the ego turns right or goes straight through the
junction, a pedestrian crosses the arm the ego is driving into."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param ego_distance = Range(15, 30)
param crossing_position = Range(3, 7)
param entry_gap = Range(1.2, 2.0)
param walking_speed = Range(1.2, 2.0)

# 2. Adversarial behaviours
behavior CrossInFrontOfEgo(speed, toLane, gap, egoLane):
    # step off the kerb once the walk to the ego's lane (toLane metres at `speed`) would reach it `gap`
    # seconds before the ego's front does; short of the lane's edge wait, if the ego has slowed down since,
    # until it is `gap` seconds away again, within 9 m, or standing (the ego's time is read every step
    # from its distance and speed, so an ego that hangs back or speeds up is still met in front of it).
    # The edge is measured from the walker's position, and the stop is ordered a step's walk early (it
    # takes effect a step later), so the walker waits outside the lane, not already in the ego's way.
    while True:
        ahead = (distance from ego to self) - 2.5
        if ahead > 0 and (ahead <= 9 or ahead / max(ego.speed, 0.1) <= toLane / speed + gap):
            break
        wait
    take SetWalkingSpeedAction(speed)
    while (egoLane.centerline.distanceTo(self.position) - 1.75) > 0.3 + speed * simulation().timestep:
        wait
    ahead = (distance from ego to self) - 2.5
    if ahead > 9 and ego.speed >= 0.5 and ahead / max(ego.speed, 0.1) > gap + 0.5:
        take SetWalkingSpeedAction(0)
        while True:
            ahead = (distance from ego to self) - 2.5
            if ahead <= 9 or ego.speed < 0.5 or ahead / max(ego.speed, 0.1) <= gap:
                break
            wait
        take SetWalkingSpeedAction(speed)
    while self.position in network.sidewalkRegion:
        wait
    while not (self.position in network.sidewalkRegion):
        wait
    do Idle() for 0.6 seconds
    take SetWalkingSpeedAction(0)

behavior Idle():
    while True:
        wait

behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=0.7 * speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; the ego turns right or goes straight, and the pedestrian
# crosses the arm it drives into, just past the junction, from either sidewalk
egoManeuvers = [m for junction in network.intersections for m in junction.maneuvers
                if m.type is ManeuverType.RIGHT_TURN or m.type is ManeuverType.STRAIGHT]
egoManeuver = Uniform(*egoManeuvers)
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
# (a negative distance to the right puts the pedestrian on the left sidewalk)
pedestrianSide = Uniform(Range(2.0, 2.7), -Range(6.2, 6.9))

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
crossSpot = new OrientedPoint at egoManeuver.endLane.centerline.pointAlongBy(globalParameters.crossing_position),
    facing roadDirection
pedestrian = new Pedestrian right of crossSpot by pedestrianSide,
    with name "pedestrian",
    facing toward crossSpot,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed, abs(pedestrianSide) - 1.75,
                                   globalParameters.entry_gap, egoManeuver.endLane)
