"""Collision-risk avoidance on a highway: the car ahead of the ego suddenly brakes."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(20, 28)
param lead_gap = Range(18, 35)
param brake_after = Range(1.5, 3.0)
param brake_headway = Range(1.0, 1.6)
param brake_strength = Range(0.6, 1.0)

# 2. Adversarial behaviours
behavior PaceThenBrake(minCruise, headway, maxWait, strength):
    # keep pace with the ego (easing off while it hangs back more than 2.5 s behind), then brake hard
    # once it is within `headway` seconds behind in this lane, its centre within 1 m of the lane's (or, after
    # maxWait seconds, within 2.5 s); an ego in another lane (changing lanes, weaving) is paced until it is back
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
    while True:
        take SetThrottleAction(0), SetBrakeAction(strength)

# 3. Road geometry: a straight multi-lane one-way highway; the ego's lane has a lane on each side
laneTriples = [(lane.sections[0]._laneToLeft.lane, lane, lane.sections[0]._laneToRight.lane)
               for lane in network.lanes
               if lane.sections[0]._laneToLeft is not None and lane.sections[0]._laneToRight is not None]
laneTriple = Uniform(*laneTriples)
egoLane = laneTriple[1]
egoS = Range(50, 1200)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
lead = new Car following roadDirection from ego for globalParameters.lead_gap,
    with name "lead",
    with speed globalParameters.ego_speed,
    with behavior PaceThenBrake(globalParameters.brake_after, globalParameters.brake_headway, 4,
                                globalParameters.brake_strength)
# one car in each neighbouring lane
traffic1 = new Car at laneTriple[0].centerline.pointAlongBy(egoS + Range(-30, 50)),
    with speed Range(20, 26), with behavior FollowLaneBehavior(target_speed=Range(20, 26))
traffic2 = new Car at laneTriple[2].centerline.pointAlongBy(egoS + Range(-30, 50)),
    with speed Range(20, 26), with behavior FollowLaneBehavior(target_speed=Range(20, 26))
