"""Opposite direction with a manoeuvre on an urban street: an oncoming car pulls out into the ego's lane
to overtake a slow truck ahead of it while the ego approaches, then returns to its own lane."""

# 1. Map and global parameters
param map = 'urban_two_way'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'CloudySunset', 'WetCloudySunset')
model scenic.domains.driving.model

param ego_speed = Range(8, 12)
param truck_distance = Range(140, 170)
param truck_speed = Range(4, 6)
param follow_gap = Range(12, 14)
param pull_out_time_gap = Range(6.0, 7.0)
param pass_extra_speed = Range(8, 10)
param lane_change_duration = Range(1.5, 2.0)
param pass_margin = Range(5, 7)

# 2. Adversarial behaviours
behavior SlideSideways(line, fromOffset, toOffset, speed, duration):
    # follow `line` at a lateral offset (metres, left positive) that slides smoothly from
    # fromOffset to toOffset within `duration` seconds, then stays there
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    i = 0
    while True:
        i = min(i + 1, steps)
        u = i / steps
        reference = fromOffset + (toOffset - fromOffset) * u * u * (3 - 2 * u)
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior OvertakeTowardEgo(slow, followSpeed, timeGap, extraSpeed, duration, margin):
    # follow the slow truck until the ego is about `timeGap` seconds away (at the closing speed of
    # the two), then pull out into the ego's lane (the lane to its left), pass the truck and pull
    # back in `margin` metres ahead of it
    home = self.laneSection.centerline
    do FollowLaneBehavior(target_speed=followSpeed) until \
        (distance from self to ego) < timeGap * max(ego.speed + self.speed, 5)
    do SlideSideways(home, 0, 3.5, followSpeed + extraSpeed, duration) until \
        (distance past slow of self) > margin
    offset = home.signedDistanceTo(self.position)
    do SlideSideways(home, offset, 0, followSpeed + extraSpeed, duration) for duration + 1 seconds
    do FollowLaneBehavior(target_speed=followSpeed + extraSpeed)

# 3. Road geometry: a two-way urban street, one lane per direction (the ego's and the oncoming one)
lanePairs = [(lane, other) for lane in network.lanes for other in network.lanes if other is not lane]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
oncomingLane = lanePair[1]
egoS = Range(60, 300)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
# both lanes are 600 m long: a negative distance counts back from the oncoming lane's end
slowTruck = new Truck at oncomingLane.centerline.pointAlongBy(-(egoS + globalParameters.truck_distance)),
    with name "truck",
    with speed globalParameters.truck_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.truck_speed)
passer = new Car at oncomingLane.centerline.pointAlongBy(
        -(egoS + globalParameters.truck_distance + globalParameters.follow_gap)),
    with name "passer",
    with speed globalParameters.truck_speed,
    with behavior OvertakeTowardEgo(slowTruck, globalParameters.truck_speed, globalParameters.pull_out_time_gap,
                                    globalParameters.pass_extra_speed, globalParameters.lane_change_duration,
                                    globalParameters.pass_margin)
