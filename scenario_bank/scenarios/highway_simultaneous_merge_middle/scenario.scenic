"""Simultaneous merge into the middle lane: the ego moves from the left lane to the middle lane
while a car on the right lane moves into the middle lane at about the same time."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(20, 26)
param other_speed_delta = Range(-1.5, 1.5)
param ego_change_after = Range(1.0, 2.5)
param other_change_offset = Range(-0.6, 0.6)
param other_offset = Range(-6, 6)

# 2. Adversarial behaviours
behavior ChangeLaneAfter(speed, after, toLeft):
    # keep the lane for `after` seconds, then move one lane over (Scenic's LaneChangeBehavior)
    do FollowLaneBehavior(target_speed=speed) for after seconds
    if toLeft:
        do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToLeft, target_speed=speed)
    else:
        do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToRight, target_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: three adjacent lanes of a straight highway (left, middle, right)
def rightOf(lane):
    section = lane.sections[0]._laneToRight
    return None if section is None else section.lane
laneTriples = [(lane, rightOf(lane), rightOf(rightOf(lane))) for lane in network.lanes
               if rightOf(lane) is not None and rightOf(rightOf(lane)) is not None]
laneTriple = Uniform(*laneTriples)
leftLane = laneTriple[0]
rightLane = laneTriple[2]
egoS = Range(50, 1200)

# 4. Spawn positions
ego = new Car at leftLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior ChangeLaneAfter(globalParameters.ego_speed, globalParameters.ego_change_after, False)
other = new Car at rightLane.centerline.pointAlongBy(egoS + globalParameters.other_offset),
    with name "other",
    with speed globalParameters.ego_speed + globalParameters.other_speed_delta,
    with behavior ChangeLaneAfter(globalParameters.ego_speed + globalParameters.other_speed_delta,
                                  globalParameters.ego_change_after + globalParameters.other_change_offset, True)
