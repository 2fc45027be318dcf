"""Lead vehicle decelerating on a highway: the car in front of the ego suddenly slows down to a lower speed."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(22, 28)
param lead_gap = Range(20, 40)
param decel_after = Range(1.0, 3.0)
param decel_trigger = Range(10, 16)
param lead_low_speed = Range(8, 15)
param decel_strength = Range(0.35, 0.55)

# 2. Adversarial behaviours
behavior DecelerateToSpeed(speed, lowSpeed, after, trigger, strength):
    # cruise with the ego, then (after a while, or earlier if the ego closes in) brake to a lower speed
    try:
        do FollowLaneBehavior(target_speed=speed) for after seconds
    interrupt when (distance from self to ego) < trigger:
        abort
    while self.speed > lowSpeed:
        take SetThrottleAction(0), SetBrakeAction(strength)
    do FollowLaneBehavior(target_speed=lowSpeed)

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
lead = new Car at egoLane.centerline.pointAlongBy(egoS + globalParameters.lead_gap),
    with name "lead",
    with speed globalParameters.ego_speed,
    with behavior DecelerateToSpeed(globalParameters.ego_speed, globalParameters.lead_low_speed,
                                    globalParameters.decel_after, globalParameters.decel_trigger,
                                    globalParameters.decel_strength)
traffic = new Car at nextLane.centerline.pointAlongBy(egoS + Range(-30, 40)),
    with speed Range(20, 27), with behavior FollowLaneBehavior(target_speed=Range(20, 27))
