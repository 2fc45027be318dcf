"""Lead vehicle stopped on an urban street: a car stands still in the ego's lane ahead while
oncoming traffic uses the other lane."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'WetCloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 13)
param stopped_gap = Range(30, 60)
param oncoming_distance = Range(40, 90)
param oncoming_speed = Range(8, 12)

# 2. Adversarial behaviours
behavior StayStopped():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

# 3. Road geometry: a two-way urban street, one lane per direction (the ego's and the oncoming one)
lanePairs = [(lane, other) for lane in network.lanes for other in network.lanes if other is not lane]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
oncomingLane = lanePair[1]
egoS = Range(60, 420)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
stopped = new Car at egoLane.centerline.pointAlongBy(egoS + globalParameters.stopped_gap),
    with name "stopped",
    with speed 0,
    with behavior StayStopped()
# both lanes are 600 m long: a negative distance counts back from the oncoming lane's end
oncoming = new Car at oncomingLane.centerline.pointAlongBy(-(egoS + globalParameters.oncoming_distance)),
    with name "oncoming",
    with speed globalParameters.oncoming_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.oncoming_speed)
