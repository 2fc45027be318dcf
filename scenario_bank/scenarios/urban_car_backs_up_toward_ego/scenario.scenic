"""Backing up into another vehicle on a town street: a car standing in the ego's lane ahead, just past a
free parking space, backs straight up toward the ego as the ego approaches, and stops in the lane."""

# 1. Map and global parameters
param map = 'urban_parking'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param backer_distance = Range(45, 60)
param back_time_gap = Range(2.5, 3.5)
param back_speed = Range(2.0, 3.0)
param back_distance = Range(6, 10)
param back_throttle = Range(0.4, 0.6)
param notice_gap = Range(1.0, 2.0)

# 2. Adversarial behaviours
behavior HoldStill():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

behavior BackUpWhenEgoNear(timeGap, speed, backDistance, throttle, noticeGap):
    # stand in the lane until the ego is about `timeGap` seconds away (never closer than 12 m), then
    # reverse straight back along the lane for `backDistance` metres and stop; the driver looks at the
    # parking space and notices the ego only when its bumper is `noticeGap` metres away (an ego that
    # stopped in time is not backed into, one that comes on is)
    while (distance past ego of self) > max(12, timeGap * ego.speed):
        take SetThrottleAction(0), SetBrakeAction(1)
    start = self.position
    while (distance from self to start) < backDistance and (distance past ego of self) - 4.5 > noticeGap:
        take SetReverseAction(True), SetThrottleAction(throttle if self.speed < speed else 0), \
            SetBrakeAction(0), SetSteerAction(0)
    while self.speed > 0.1:
        take SetThrottleAction(0), SetBrakeAction(1)
    do HoldStill()

# 3. Road geometry: a two-way town street with a parking lane at each kerb; the ego's lane
egoLane = Uniform(*network.lanes)
egoS = Range(40, 400)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
backer = new Car at egoLane.centerline.pointAlongBy(egoS + globalParameters.backer_distance),
    with name "backer",
    with speed 0,
    with behavior BackUpWhenEgoNear(globalParameters.back_time_gap, globalParameters.back_speed,
                                    globalParameters.back_distance, globalParameters.back_throttle,
                                    globalParameters.notice_gap)
# the free parking space the backer backs up to, between two parked cars
spotBehind = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + globalParameters.backer_distance - 20),
    facing roadDirection
parkedBehind = new Car right of spotBehind by 2.0, facing spotBehind.heading,
    with regionContainedIn everywhere,
    with speed 0,
    with behavior HoldStill()
spotAhead = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + globalParameters.backer_distance + 2),
    facing roadDirection
parkedAhead = new Car right of spotAhead by 2.0, facing spotAhead.heading,
    with regionContainedIn everywhere,
    with speed 0,
    with behavior HoldStill()
