"""Insertion on a highway: a car from the on-ramp merges in front of the ego."""

# 1. Map and global parameters
param map = 'highway_onramp'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetSunset')
model scenic.domains.driving.model

param ego_speed = Range(18, 24)
param merger_speed = Range(16, 24)
param merge_delay = Range(0.5, 2.5)

# 2. Adversarial behaviours
behavior MergeFromRamp(speed, accelLane, delay):
    do FollowLaneBehavior(target_speed=speed) until self._lane is accelLane
    do FollowLaneBehavior(target_speed=speed) for delay seconds
    do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToLeft, target_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: three-lane highway, a one-lane on-ramp joining an acceleration lane
# (one-element Uniforms keep positions along these lanes lazily sampled)
rampLane = Uniform(network.elements['road4_lane0'])
accelLane = network.elements['road2_lane0']
rightLane = Uniform(network.elements['road1_lane0'])

# 4. Spawn positions
ego = new Car at rightLane.centerline.pointAlongBy(Range(280, 390)),
    with speed globalParameters.ego_speed
merger = new Car at rampLane.centerline.pointAlongBy(Range(60, 180)),
    with speed globalParameters.merger_speed,
    with behavior MergeFromRamp(globalParameters.merger_speed, accelLane, globalParameters.merge_delay)
traffic = new Car following roadDirection from ego for Range(25, 60),
    with speed Range(20, 25), with behavior FollowLaneBehavior(target_speed=Range(20, 25))
