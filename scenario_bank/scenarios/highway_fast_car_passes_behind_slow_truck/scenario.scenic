"""Following vehicle making a manoeuvre on a highway: the ego follows a slow truck and the lane to its
left looks open, but a faster car comes up from behind in that lane (the car an ego that pulls out to
pass the truck would be struck by), passes the ego, moves into the gap between the ego and the
truck and brakes hard behind the truck."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'SoftRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(20, 25)
param truck_speed_share = Range(0.6, 0.72)
param truck_gap = Range(95, 120)
param passer_start_gap = Range(10, 22)
param passer_extra_speed = Range(8, 11)
param move_in_gap = Range(4, 8)
param lane_change_duration = Range(1.6, 2.2)
param brake_distance = Range(12, 20)
param brake_strength = Range(0.6, 0.9)

# 2. Adversarial behaviours
def approachLimit(truckSpeed, gap, brakeDistance):
    # the fastest speed from which braking at 5 m/s^2 still reaches the hard-braking point `brakeDistance`
    # + 10 m behind the truck no more than 5 m/s faster than it (it only binds for an ego that rushes
    # up on the truck, where the gap is short)
    room = max(0, gap - brakeDistance - 10)
    return truckSpeed + 5 + math.sqrt(2 * 5 * room)

behavior SlideToLane(section, truck, brakeDistance, duration):
    # change lanes by tracking a reference that slides smoothly from the current lateral offset
    # to the centre of the target lane section within `duration` seconds, at the ego's speed
    # (+1 m/s; still closing in on the truck behind an ego that hangs back) unless that is too fast to
    # brake behind the truck
    line = section.centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    startOffset = line.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        speed = min(max(ego.speed + 1, truck.speed + 4),
                    approachLimit(truck.speed, distance past self of truck, brakeDistance))
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer, max_brake=1.0)
        pastSteer = steer

behavior PassAndMoveIn(truck, extraSpeed, moveInGap, duration, brakeDistance, strength):
    # triggers on the ego: come up from behind in the next lane at `extraSpeed` above the ego's speed,
    # and once `moveInGap` metres ahead of it move into its lane (matching the ego's speed while
    # changing lanes, so it lands in the gap behind the truck); close in on the truck at the ego's
    # speed, never too fast to brake behind it, and, `brakeDistance` metres behind it, brake hard to
    # the truck's speed
    # (distance past ego of self: how far self is ahead of the ego)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    while (distance past ego of self) <= moveInGap + 5:
        throttle = lonControl.run_step(ego.speed + extraSpeed - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, 0)
    do SlideToLane(self.laneSection.laneToRight, truck, brakeDistance, duration)
    pastSteer = 0
    while (distance past self of truck) > brakeDistance + 10:
        speed = min(max(ego.speed, truck.speed + 4),
                    approachLimit(truck.speed, distance past self of truck, brakeDistance))
        throttle = lonControl.run_step(speed - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer, max_brake=1.0)
        pastSteer = steer
    while self.speed > truck.speed:
        take SetThrottleAction(0), SetBrakeAction(strength)
    do FollowLaneBehavior(target_speed=truck.speed)

behavior SlowTruck(speed):
    # drive on at `speed`, but while the ego is more than 60 m behind, slower than the ego (an ego that hangs
    # back still comes up behind the truck)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    wanted = speed
    pastSteer = 0
    while True:
        if (distance past ego of self) > 60:
            wanted = max(5, min(speed, ego.speed - 4))
        throttle = lonControl.run_step(wanted - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

# 3. Road geometry: a straight multi-lane highway; the ego's lane and the lane to its left
lanePairs = [(lane, lane.sections[0]._laneToLeft.lane) for lane in network.lanes
             if lane.sections[0]._laneToLeft is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
passLane = lanePair[1]
egoS = Range(80, 1000)
truckSpeed = globalParameters.ego_speed * globalParameters.truck_speed_share

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
truck = new Truck at egoLane.centerline.pointAlongBy(egoS + globalParameters.truck_gap),
    with name "truck",
    with speed truckSpeed,
    with behavior SlowTruck(truckSpeed)
passer = new Car at passLane.centerline.pointAlongBy(egoS - globalParameters.passer_start_gap),
    with name "passer",
    with speed globalParameters.ego_speed + globalParameters.passer_extra_speed,
    with behavior PassAndMoveIn(truck, globalParameters.passer_extra_speed, globalParameters.move_in_gap,
                                globalParameters.lane_change_duration, globalParameters.brake_distance,
                                globalParameters.brake_strength)
