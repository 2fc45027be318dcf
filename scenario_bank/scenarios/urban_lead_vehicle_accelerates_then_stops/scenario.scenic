"""Lead vehicle accelerating on an urban street: a car waiting in the ego's lane drives off as the ego
approaches, speeds up ahead of it and then stops abruptly in front of it."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(7, 10)
param lead_distance = Range(40, 55)
param start_time_gap = Range(2.0, 3.0)
param start_throttle = Range(0.7, 1.0)
param follow_time_gap = Range(1.2, 1.8)
param follow_for = Range(1.5, 2.5)
param brake_strength = Range(0.8, 1.0)

# 2. Adversarial behaviours
behavior HoldStill():
    while True:
        take SetThrottleAction(0), SetBrakeAction(1)

behavior LeadEgo(line, timeGap, seconds):
    # drive ahead of the ego for `seconds`, keeping about `timeGap` seconds of its speed between them (an ego
    # that hangs back or rushes keeps the same gap to a lead that adapts); end early when the ego closes in
    # so fast that it would reach the lead within 2 s
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    for step in range(int(seconds / simulation().timestep)):
        gap = (distance past ego of self) - 5
        if gap < 2 * (ego.speed - self.speed):
            break
        wanted = max(3, ego.speed + 0.5 * (timeGap * max(ego.speed, 3) - gap))
        throttle = lonControl.run_step(min(wanted, 15) - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior DriveOffThenStop(startGap, throttle, followGap, followFor, strength):
    # wait until the ego is `startGap` seconds away (never closer than 12 m), or near and nearly stopped (an
    # ego that hangs back), drive off hard until faster than the ego (at most 14 m/s), lead it for a moment,
    # then brake to a standstill in front of it
    line = self.laneSection.centerline
    while ((distance past ego of self) > max(12, startGap * ego.speed)
           and not ((distance past ego of self) < 40 and ego.speed < 2)):
        take SetThrottleAction(0), SetBrakeAction(1)
    while self.speed < min(max(ego.speed, 4) + 2, 14):
        take SetThrottleAction(throttle), SetBrakeAction(0), SetSteerAction(0)
    do LeadEgo(line, followGap, followFor)
    while self.speed > 0.1:
        take SetThrottleAction(0), SetBrakeAction(strength)
    do HoldStill()

# 3. Road geometry: a two-way urban street; the ego's lane
egoLane = Uniform(*network.lanes)
egoS = Range(40, 400)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
lead = new Car at egoLane.centerline.pointAlongBy(egoS + globalParameters.lead_distance),
    with name "lead",
    with speed 0,
    with behavior DriveOffThenStop(globalParameters.start_time_gap, globalParameters.start_throttle,
                                   globalParameters.follow_time_gap, globalParameters.follow_for,
                                   globalParameters.brake_strength)
