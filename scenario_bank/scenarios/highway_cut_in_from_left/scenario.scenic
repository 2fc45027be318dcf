"""Cut-in from the left on a highway: a faster car in the lane to the ego's left passes it and
changes into the ego's lane just ahead of it."""

# 1. Map and global parameters
param map = 'highway_straight'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'HardRainNoon')
model scenic.domains.driving.model

param ego_speed = Range(18, 25)
param cutter_extra_speed = Range(4, 8)
param start_offset = Range(-12, -2)
param cut_in_gap = Range(5, 11)
param speed_after_cut_in = Range(-3, 1)
param lane_change_duration = Range(1.8, 3.0)

# 2. Adversarial behaviours
behavior SlideToLane(section, extraSpeed, duration):
    # change lanes by tracking a reference that slides smoothly from the current lateral offset
    # to the centre of the target lane section within `duration` seconds, `extraSpeed` faster than the ego
    line = section.centerline
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    startOffset = line.signedDistanceTo(self.position)
    steps = max(1, int(duration / simulation().timestep))
    pastSteer = 0
    for i in range(steps):
        u = (i + 1) / steps
        reference = startOffset * (1 - u * u * (3 - 2 * u))
        throttle = lonControl.run_step(ego.speed + extraSpeed - self.speed)
        steer = latControl.run_step(line.signedDistanceTo(self.position) - reference)
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer

behavior CutInToTheRight(extraSpeed, gap, speedAfter, duration):
    # triggers on the ego: pass it in the next lane `extraSpeed` faster than it, whatever its speed (an ego
    # that rushes is still passed), then change into its lane once `gap` metres ahead of it and settle
    # `speedAfter` above (below, when negative) the ego's speed at that moment
    # (distance past ego of self: how far self is ahead of the ego along self's heading)
    lonControl, latControl = simulation().getLaneFollowingControllers(self)
    pastSteer = 0
    while (distance past ego of self) <= gap:
        throttle = lonControl.run_step(ego.speed + extraSpeed - self.speed)
        steer = latControl.run_step(self.lane.centerline.signedDistanceTo(self.position))
        take RegulatedControlAction(throttle, steer, pastSteer)
        pastSteer = steer
    do SlideToLane(self.laneSection.laneToRight, extraSpeed, duration)
    do FollowLaneBehavior(target_speed=max(ego.speed + speedAfter, 5))

# 3. Road geometry: a straight multi-lane highway; the ego's lane and the lane to its left
lanePairs = [(lane, lane.sections[0]._laneToLeft.lane) for lane in network.lanes
             if lane.sections[0]._laneToLeft is not None]
lanePair = Uniform(*lanePairs)
egoLane = lanePair[0]
cutterLane = lanePair[1]
egoS = Range(50, 1100)

# 4. Spawn positions
ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed)
cutter = new Car at cutterLane.centerline.pointAlongBy(egoS + globalParameters.start_offset),
    with name "cutter",
    with speed globalParameters.ego_speed + globalParameters.cutter_extra_speed,
    with behavior CutInToTheRight(globalParameters.cutter_extra_speed,
                                  globalParameters.cut_in_gap,
                                  globalParameters.speed_after_cut_in,
                                  globalParameters.lane_change_duration)
traffic = new Car at egoLane.centerline.pointAlongBy(egoS + Range(45, 80)),
    with speed globalParameters.ego_speed + 2,
    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed + 2)
