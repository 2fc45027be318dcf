"""Pull back in on an urban highway: a faster car overtakes the ego and cuts back in ahead of it."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon')
model scenic.domains.driving.model

param ego_speed = Range(14, 18)
param overtaker_extra_speed = Range(4, 8)
param start_gap = Range(12, 22)
param return_gap = Range(4, 10)
param slow_down_to = Range(10, 14)

# 2. Adversarial behaviours
behavior OvertakeAndPullBackIn(speed, target, returnGap, slowSpeed):
    do FollowLaneBehavior(target_speed=speed) until (distance from self to target) < 12
    do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToLeft, target_speed=speed)
    do FollowLaneBehavior(target_speed=speed) until (distance past target of self) > returnGap
    do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToRight, target_speed=speed)
    do FollowLaneBehavior(target_speed=slowSpeed)

# 3. Road geometry: a straight multi-lane road; the ego keeps a lane that has a lane to its left
egoLane = Uniform(*filter(lambda l: l.sections[0]._laneToLeft is not None, network.lanes))

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(Range(100, 1200)),
    with speed globalParameters.ego_speed
overtaker = new Car following roadDirection from ego for -globalParameters.start_gap,
    with speed globalParameters.ego_speed + globalParameters.overtaker_extra_speed,
    with behavior OvertakeAndPullBackIn(globalParameters.ego_speed + globalParameters.overtaker_extra_speed,
                                        ego, globalParameters.return_gap, globalParameters.slow_down_to)
traffic = new Car offset by (Uniform(-3.5, 3.5), Range(30, 70)), with regionContainedIn road,
    with speed Range(14, 18), with behavior FollowLaneBehavior(target_speed=Range(14, 18))
