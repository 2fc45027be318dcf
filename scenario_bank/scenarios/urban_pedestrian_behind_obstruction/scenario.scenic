"""Pedestrian behind an obstruction on an urban street: a pedestrian steps out from behind a truck
parked at the far curb and crosses in front of the ego."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param crossing_distance = Range(35, 55)
param hidden_gap = Range(0.8, 2.0)
param entry_gap = Range(1.0, 2.0)
param walking_speed = Range(1.6, 2.4)
param kerb_offset = Range(5.5, 6.2)

# 2. Adversarial behaviours
behavior CrossInFrontOfEgo(speed, toLane, gap):
    # step off the kerb once the walk to the ego's lane (toLane metres at `speed`) would reach it `gap`
    # seconds before the ego's front does; at the lane's edge wait, if the ego has slowed down since,
    # until it is `gap` seconds away again, within 9 m, or standing (the ego's time is read every step
    # from its distance and speed, so an ego that hangs back or speeds up is still met in front of it)
    while True:
        ahead = -(distance past self of ego) - 2.5
        if ahead > 0 and (ahead <= 9 or ahead / max(ego.speed, 0.1) <= toLane / speed + gap):
            break
        wait
    take SetWalkingSpeedAction(speed)
    walked = 0
    while walked < toLane - 0.4:
        walked += speed * simulation().timestep
        wait
    ahead = -(distance past self of ego) - 2.5
    if ahead > 9 and ego.speed >= 0.5 and ahead / max(ego.speed, 0.1) > gap + 0.5:
        take SetWalkingSpeedAction(0)
        while True:
            ahead = -(distance past self of ego) - 2.5
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

# 3. Road geometry: a two-way urban street with sidewalks; the truck parks in the oncoming lane
egoLane = Uniform(*network.lanes)
egoS = Range(60, 450)
crossS = egoS + globalParameters.crossing_distance

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
# the truck (9 m long) ends just before the crossing point, seen from the ego
truckSpot = new OrientedPoint at egoLane.centerline.pointAlongBy(crossS - 4.5 - globalParameters.hidden_gap),
    facing roadDirection
parked = new Truck left of truckSpot by Range(2.5, 2.7), facing roadDirection, with speed 0,
    with name "parked"
crossSpot = new OrientedPoint at egoLane.centerline.pointAlongBy(crossS), facing roadDirection
pedestrian = new Pedestrian left of crossSpot by globalParameters.kerb_offset,
    with name "pedestrian",
    facing crossSpot.heading - 90 deg,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed, globalParameters.kerb_offset - 1.75,
                                   globalParameters.entry_gap)
