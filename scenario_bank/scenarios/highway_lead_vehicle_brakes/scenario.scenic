"""Collision-risk avoidance on a highway: the car ahead of the ego suddenly brakes."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(20, 28)
param lead_gap = Range(18, 35)
param brake_after = Range(1.5, 4.0)
param brake_strength = Range(0.6, 1.0)

# 2. Adversarial behaviours
behavior SuddenBrake(speed, after, strength):
    do FollowLaneBehavior(target_speed=speed) for after seconds
    while True:
        take SetThrottleAction(0), SetBrakeAction(strength)

# 3. Road geometry: a straight multi-lane one-way highway
egoLane = Uniform(*network.lanes)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(Range(50, 1200)),
    with speed globalParameters.ego_speed
lead = new Car following roadDirection from ego for globalParameters.lead_gap,
    with name "lead",
    with speed globalParameters.ego_speed,
    with behavior SuddenBrake(globalParameters.ego_speed, globalParameters.brake_after, globalParameters.brake_strength)
traffic1 = new Car offset by (Uniform(-3.5, 3.5), Range(-30, 50)), with regionContainedIn road,
    with speed Range(20, 26), with behavior FollowLaneBehavior(target_speed=Range(20, 26))
traffic2 = new Car offset by (Uniform(-7, 7), Range(-30, 50)), with regionContainedIn road,
    with speed Range(20, 26), with behavior FollowLaneBehavior(target_speed=Range(20, 26))
