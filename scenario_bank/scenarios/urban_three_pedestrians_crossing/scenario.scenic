"""Three pedestrians cross in the middle of an urban road in front of the ego: one from left to
right and two from right to left."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'SoftRainSunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param crossing_distance = Range(35, 50)
param trigger_time = Range(2.2, 3.5)
param left_head_start = Range(0.8, 1.8)
param walking_speed = Range(1.1, 1.8)

# 2. Adversarial behaviours
behavior CrossWhenEgoNear(speed, triggerTime):
    # step off the sidewalk once the ego is about triggerTime seconds away, walk across, stop on the far side
    while (distance from self to ego) > max(8, triggerTime * ego.speed):
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
leftToRight = new Pedestrian left of spotLeft by Range(5.5, 6.2),
    with name "leftToRight",
    facing spotLeft.heading - 90 deg,
    with behavior CrossWhenEgoNear(globalParameters.walking_speed,
                                   globalParameters.trigger_time + globalParameters.left_head_start)
rightToLeft1 = new Pedestrian right of spotRight1 by Range(2.0, 2.7),
    with name "rightToLeft1",
    facing spotRight1.heading + 90 deg,
    with behavior CrossWhenEgoNear(globalParameters.walking_speed + Range(-0.2, 0.2),
                                   globalParameters.trigger_time)
rightToLeft2 = new Pedestrian right of spotRight2 by Range(2.0, 2.7),
    with name "rightToLeft2",
    facing spotRight2.heading + 90 deg,
    with behavior CrossWhenEgoNear(globalParameters.walking_speed + Range(-0.2, 0.2),
                                   globalParameters.trigger_time + Range(-0.4, 0.4))
