"""Lead vehicle stopped on a highway: a broken-down car stands still in the ego's lane ahead."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'WetCloudySunset', 'MidRainyNoon')
model scenic.domains.driving.model

param ego_speed = Range(22, 28)
param stopped_gap = Range(60, 120)
param traffic_speed = Range(20, 27)

# 2. Adversarial behaviours
behavior StayStopped():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

# 3. Road geometry: a straight four-lane one-way highway; the ego's lane and one next to it
lanePairs = [(lane, side.lane) for lane in network.lanes
             for side in (lane.sections[0]._laneToLeft, lane.sections[0]._laneToRight) if side is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
nextLane = lanePair[1]
egoS = Range(50, 1200)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
stopped = new Car at egoLane.centerline.pointAlongBy(egoS + globalParameters.stopped_gap),
    with name "stopped",
    with speed 0,
    with behavior StayStopped()
traffic = new Car at nextLane.centerline.pointAlongBy(egoS + Range(-25, 25)),
    with speed globalParameters.traffic_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.traffic_speed)
