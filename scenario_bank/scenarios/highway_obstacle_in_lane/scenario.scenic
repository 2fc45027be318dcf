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
param follower_gap = Range(12, 20)

# 2. Adversarial behaviours
behavior StayAlongside(offset, cruise):
    # hold `offset` metres ahead of the ego (negative: behind it) in the next lane, whatever the ego's
    # speed (as quick to speed up and brake as the ego): an ego that brakes early or speeds up still finds the lane
    # beside it taken; once the ego is about to stop behind the load, drive on at `cruise`, as traffic
    # in a free lane does
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    line = self.lane.centerline
    pastSteer = 0
    while ego.speed >= 3.0:
        ahead = -(distance past self of ego)
        target = min(max(ego.speed + 0.6 * (offset - ahead), 0), ego.speed + 6)
        throttle = lonControl.run_step(target - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer, max_throttle=1.0, max_brake=1.0)
        pastSteer = steer
    do FollowLaneBehavior(target_speed=cruise)

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
    with speed globalParameters.ego_speed,
    with behavior StayAlongside(globalParameters.blocker_offset, globalParameters.ego_speed)
follower = new Car at leftLane.centerline.pointAlongBy(egoS + globalParameters.blocker_offset - globalParameters.follower_gap),
    with name "follower",
    with speed globalParameters.ego_speed,
    with behavior StayAlongside(globalParameters.blocker_offset - globalParameters.follower_gap,
                                globalParameters.ego_speed)
