"""Obstacle in the lane on a highway: a lost load lies in the ego's lane ahead, and cars in the
lane to its left keep it from changing lanes easily."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(20, 27)
param obstacle_gap = Range(60, 110)
param obstacle_width = Range(1.2, 2.4)
param obstacle_length = Range(0.8, 2.5)
param blocker_offset = Range(-8, 4)
param blocker_speed_delta = Range(-0.5, 0.8)

# 2. Adversarial behaviours
behavior StayAlongside(speed):
    # the blocking car holds about the ego's speed in the next lane
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a straight multi-lane highway; the ego's lane and the lane to its left
lanePairs = [(lane, lane.sections[0]._laneToLeft.lane) for lane in network.lanes
             if lane.sections[0]._laneToLeft is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
leftLane = lanePair[1]
egoS = Range(50, 1100)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
obstacle = new Obstacle at egoLane.centerline.pointAlongBy(egoS + globalParameters.obstacle_gap),
    with name "obstacle",
    with width globalParameters.obstacle_width,
    with length globalParameters.obstacle_length
blocker = new Car at leftLane.centerline.pointAlongBy(egoS + globalParameters.blocker_offset),
    with name "blocker",
    with speed globalParameters.ego_speed + globalParameters.blocker_speed_delta,
    with behavior StayAlongside(globalParameters.ego_speed + globalParameters.blocker_speed_delta)
follower = new Car at leftLane.centerline.pointAlongBy(egoS + globalParameters.blocker_offset - Range(12, 20)),
    with name "follower",
    with speed globalParameters.ego_speed + globalParameters.blocker_speed_delta,
    with behavior StayAlongside(globalParameters.ego_speed + globalParameters.blocker_speed_delta)
