"""Lead vehicle at a lower constant speed on a highway: the ego closes in on a slower truck that keeps
its lane and its speed, while a car in the next lane is alongside the ego."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(24, 30)
param lead_speed_share = Range(0.45, 0.65)
param lead_gap = Range(60, 95)

# 2. Adversarial behaviours
# (none beyond the driving domain's lane following: the point of this scenario is a lead vehicle
# that keeps a constant speed well below the ego's, so the ego closes in whatever it does)

# 3. Road geometry: a straight four-lane one-way highway; the ego's lane and one next to it
lanePairs = [(lane, side.lane) for lane in network.lanes
             for side in (lane.sections[0]._laneToLeft, lane.sections[0]._laneToRight) if side is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
nextLane = lanePair[1]
egoS = Range(50, 1000)
leadSpeed = globalParameters.ego_speed * globalParameters.lead_speed_share

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
lead = new Truck at egoLane.centerline.pointAlongBy(egoS + globalParameters.lead_gap),
    with name "lead",
    with speed leadSpeed,
    with behavior FollowLaneBehavior(target_speed=leadSpeed)
traffic = new Car at nextLane.centerline.pointAlongBy(egoS + Range(-15, 5)),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
