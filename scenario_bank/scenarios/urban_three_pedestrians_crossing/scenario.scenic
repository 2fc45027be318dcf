"""Three pedestrians cross in the middle of an urban road in front of the ego: one from left to
right and two from right to left."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param crossing_distance = Range(60, 80)
param entry_gap = Range(1.4, 2.2)
param left_kerb = Range(5.5, 6.2)
param walking_speed = Range(1.1, 1.8)

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

# 3. Road geometry: a two-way urban street with a sidewalk on each side
egoLane = Uniform(*network.lanes)
egoS = Range(60, 450)
crossS = egoS + globalParameters.crossing_distance

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
spotLeft = new OrientedPoint at egoLane.centerline.pointAlongBy(crossS), facing roadDirection
spotRight1 = new OrientedPoint at egoLane.centerline.pointAlongBy(crossS - Range(1.2, 2.5)), facing roadDirection
spotRight2 = new OrientedPoint at egoLane.centerline.pointAlongBy(crossS + Range(1.2, 2.5)), facing roadDirection
leftToRight = new Pedestrian left of spotLeft by globalParameters.left_kerb,
    with name "leftToRight",
    facing spotLeft.heading - 90 deg,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed, globalParameters.left_kerb - 1.75,
                                    globalParameters.entry_gap)
rightToLeft1 = new Pedestrian right of spotRight1 by 2.7,
    with name "rightToLeft1",
    facing spotRight1.heading + 90 deg,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed + Range(-0.2, 0.2), 0.95,
                                    globalParameters.entry_gap + Range(-0.3, 0.3))
rightToLeft2 = new Pedestrian right of spotRight2 by 2.7,
    with name "rightToLeft2",
    facing spotRight2.heading + 90 deg,
    with behavior CrossInFrontOfEgo(globalParameters.walking_speed + Range(-0.2, 0.2), 0.95,
                                    globalParameters.entry_gap + Range(-0.3, 0.3))
