"""Parked car pulling out on a town street: a car parked at the kerb ahead of the ego pulls out of its
parking space into the ego's lane shortly before the ego reaches it."""

# 1. Map and global parameters
param map = 'urban_parking'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param parked_distance = Range(45, 70)
param pull_out_time_gap = Range(1.8, 2.8)
param pull_out_speed = Range(4, 6)
param pull_out_steer = Range(0.22, 0.3)

# 2. Adversarial behaviours
behavior HoldStill():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

behavior SteerInto(line, speed, maxSteer):
    # pull out of the parking lane onto `line` (the driving lane beside it): steer at most maxSteer rad
    # off the road's heading toward it while speeding up to `speed`, then follow the lane
    reference = self.heading
    while abs(line.signedDistanceTo(self.position)) > 0.3 or abs(self.heading - reference) > 0.05:
        offset = line.signedDistanceTo(self.position)
        wanted = max(-maxSteer, min(maxSteer, -0.25 * offset))
        steer = max(-0.4, min(0.4, -1.5 * (wanted - (self.heading - reference))))
        take SetThrottleAction(0.6 if self.speed < speed else 0), SetBrakeAction(0), SetSteerAction(steer)
    do FollowLaneBehavior(target_speed=speed)

behavior PullOutWhenEgoNear(line, timeGap, speed, maxSteer):
    # stay parked until the ego is about timeGap seconds away (at its current speed; never closer than
    # 10 m), then pull out into its lane in front of it
    while (distance past ego of self) > max(10, timeGap * ego.speed):
        take SetThrottleAction(0), SetBrakeAction(1)
    do SteerInto(line, speed, maxSteer)

# 3. Road geometry: a two-way town street with a parking lane at each kerb; the ego's lane, and a
# parking space on the parking lane to its right
egoLane = Uniform(*network.lanes)
egoS = Range(40, 400)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
parkingSpot = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + globalParameters.parked_distance),
    facing roadDirection
parked = new Car right of parkingSpot by Range(1.9, 2.1), facing parkingSpot.heading,
    with name "parked",
    with regionContainedIn everywhere,
    with speed 0,
    with behavior PullOutWhenEgoNear(egoLane.centerline, globalParameters.pull_out_time_gap,
                                     globalParameters.pull_out_speed, globalParameters.pull_out_steer)
require network.shoulderAt(parked) is not None
