"""Lead vehicle decelerating on a highway: the car in front of the ego suddenly slows down to a lower speed."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(22, 28)
param lead_gap = Range(20, 40)
param decel_after = Range(1.0, 3.0)
param decel_headway = Range(0.9, 1.5)
param lead_low_speed = Range(8, 15)
param decel_strength = Range(0.35, 0.55)

# 2. Adversarial behaviours
behavior PaceThenDecelerate(lowSpeed, minCruise, headway, maxWait, strength):
    # keep pace with the ego (easing off while it hangs back more than 2.5 s behind), then brake down to
    # lowSpeed once it is within `headway` seconds behind in this lane, its centre within 1 m of the lane's (or,
    # after maxWait seconds, within 2.5 s); an ego in another lane (changing lanes, weaving) is paced until it is back
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    line = self.lane.centerline
    pastSteer = 0
    elapsed = 0
    while True:
        egoHeadway = ((distance past ego of self) - 5) / max(ego.speed, 1)
        egoBehind = abs(line.signedDistanceTo(ego.position)) < 1 and (distance past ego of self) > 0
        if elapsed >= minCruise and egoBehind and (egoHeadway <= headway or (elapsed >= maxWait and egoHeadway <= 2.5)):
            break
        target = ego.speed - 2 if egoHeadway > 2.5 else ego.speed
        throttle = lonControl.run_step(target - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
        elapsed += simulation().timestep
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
    with behavior PaceThenDecelerate(globalParameters.lead_low_speed, globalParameters.decel_after,
                                     globalParameters.decel_headway, 4, globalParameters.decel_strength)
traffic = new Car at nextLane.centerline.pointAlongBy(egoS + Range(-30, 40)),
    with speed Range(20, 27), with behavior FollowLaneBehavior(target_speed=Range(20, 27))
