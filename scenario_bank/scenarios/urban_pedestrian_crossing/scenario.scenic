"""Pedestrian crossing in an urban area: a pedestrian steps off the sidewalk in front of the ego."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudySunset', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 13)
param crossing_distance = Range(35, 55)
param trigger_distance = Range(18, 30)
param walking_speed = Range(1.0, 2.0)

# 2. Adversarial behaviours
behavior CrossWhenClose(speed, trigger):
    while (distance from self to ego) > trigger:
        wait
    while True:
        take SetWalkingSpeedAction(speed)

# 3. Road geometry: a two-way urban street with sidewalks on both sides
egoLane = Uniform(*network.lanes)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(Range(60, 460)),
    with speed globalParameters.ego_speed
spot = new OrientedPoint following roadDirection from ego for globalParameters.crossing_distance
pedestrian = new Pedestrian right of spot by Range(2.6, 3.2),
    with name "pedestrian",
    facing spot.heading + 90 deg,
    with behavior CrossWhenClose(globalParameters.walking_speed, globalParameters.trigger_distance)
oncomingSpot = new OrientedPoint following roadDirection from ego for Range(30, 90)
oncoming = new Car left of oncomingSpot by 2.5, facing roadDirection, with speed Range(8, 12),
    with name "oncoming",
    with behavior FollowLaneBehavior(target_speed=Range(8, 12))
