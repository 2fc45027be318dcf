"""Pedestrian crossing in an urban area: a pedestrian steps off the sidewalk in front of the ego."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudySunset', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 13)
param crossing_distance = Range(35, 55)
param entry_gap = Range(1.2, 2.0)
param kerb_offset = Range(2.6, 3.0)
param walking_speed = Range(1.0, 2.0)

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

# 3. Road geometry: a two-way urban street with sidewalks on both sides
egoLane = Uniform(*network.lanes)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(Range(60, 460)),
    with speed globalParameters.ego_speed
spot = new OrientedPoint following roadDirection from ego for globalParameters.crossing_distance
pedestrian = new Pedestrian right of spot by globalParameters.kerb_offset,
    with name "pedestrian",
    facing spot.heading + 90 deg,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed, globalParameters.kerb_offset - 1.75,
                                    globalParameters.entry_gap)
oncomingSpot = new OrientedPoint following roadDirection from ego for Range(30, 90)
oncoming = new Car left of oncomingSpot by 2.5, facing roadDirection, with speed Range(8, 12),
    with name "oncoming",
    with behavior FollowLaneBehavior(target_speed=Range(8, 12))
