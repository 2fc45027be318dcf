"""Insertion on a highway: a car from the on-ramp merges in front of the ego."""

# 1. Map and global parameters
param map = 'highway_onramp'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(18, 24)
param merger_lead = Range(6, 12)
param merger_extra_speed = Range(1, 4)
param lane_change_duration = Range(1.8, 2.6)
param ramp_speed = Range(10, 14)

# 2. Adversarial behaviours
behavior SlideToLane(section, speed, duration):
    # change lanes by tracking a reference that slides smoothly from the current lateral offset
    # to the centre of the target lane section within `duration` seconds
    line = section.centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    startOffset = line.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior MergeAheadOfEgo(accelLane, lead, extraSpeed, duration):
    # triggers on the ego: down the ramp, match speed so as to stay `lead` metres ahead of the
    # ego (distance past ego of self: how far self is ahead of it), never more than 6 m/s slower or
    # 8 m/s faster than the ego, accelerating as hard as it must to keep up with an ego that rushes;
    # once in the acceleration lane and ahead by `lead`, slide into the ego's lane
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while not (self.lane is accelLane and (distance past ego of self) > lead):
        gapError = lead + 3 - (distance past ego of self)
        speed = max(8, min(40, ego.speed + max(-6, min(8, 0.4 * gapError))))
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer, max_throttle=1.0)
        pastSteer = steer
    do SlideToLane(self.laneSection.laneToLeft, ego.speed + extraSpeed, duration)
    do FollowLaneBehavior(target_speed=ego.speed + extraSpeed)

# 3. Road geometry: three-lane highway, a one-lane on-ramp joining an acceleration lane
# (one-element Uniforms keep positions along these lanes lazily sampled)
rampLane = Uniform(network.elements['road4_lane0'])
accelLane = network.elements['road2_lane0']
rightLane = Uniform(network.elements['road1_lane0'])

# 4. Spawn positions
ego = new Car at rightLane.centerline.pointAlongBy(Range(340, 420)),
    with speed globalParameters.ego_speed
merger = new Car at rampLane.centerline.pointAlongBy(Range(120, 200)),
    with name "merger",
    with speed globalParameters.ramp_speed,
    with behavior MergeAheadOfEgo(accelLane, globalParameters.merger_lead, globalParameters.merger_extra_speed,
                                  globalParameters.lane_change_duration)
traffic = new Car following roadDirection from ego for Range(45, 70),
    with speed Range(22, 26), with behavior FollowLaneBehavior(target_speed=Range(22, 26))
