"""Right turn into the ego's path at a crossroads: a car waiting on the side road pulls out as the
ego approaches and turns right into the ego's lane just ahead of it."""

# 1. Map and global parameters
param map = 'urban_crossroads'
param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon', 'ClearSunset', 'WetCloudyNoon')
model scenic.domains.driving.model

param ego_speed = Range(8, 11)
param ego_distance = Range(40, 60)
param turner_speed = Range(7, 10)
param turner_wait_position = Range(2, 6)
param entry_lead = Range(0.9, 1.4)

# 2. Adversarial behaviours
def timeToCover(distance, speed, top):
    # seconds to drive `distance` metres from `speed`, speeding up at 2.5 m/s2 (the controllers' most
    # throttle) to `top`
    speed = min(max(speed, 0), top)
    ramp = (top * top - speed * speed) / 5.0
    if distance <= ramp:
        return ((speed * speed + 5.0 * distance) ** 0.5 - speed) / 2.5
    return (top - speed) / 2.5 + (distance - ramp) / top

def egoFarFrom(car, point, ownTime, lead):
    # whether the car (the ego) is more than 12 m from `point` and more than ownTime + lead seconds from
    # it at its speed now (the distance from its front)
    ahead = (distance from car to point) - 2.5
    return ahead > 12 and ahead / max(car.speed, 0.1) > ownTime + lead

behavior TurnInAheadOfEgo(speed, route, egoWay, lead):
    # the turner comes into the ego's path where its turn passes within half a lane of the ego's way
    # (`merge`); it pulls out of the side road once it would get there `lead` seconds before the ego's
    # front at the ego's speed, stops at the mouth of the junction, clear of the ego's lane, if the ego
    # has slowed down since, and turns in when the ego is `lead` seconds (plus the turner's own time to
    # the merge) or 12 m away again (the ego's time is read every step from its distance and speed, so
    # an ego that hangs back or speeds up still has the turner cut in just ahead of it)
    turn = route[1].centerline
    turnSpeed = 0.7 * speed
    samples = [0.25 * k for k in range(int(4 * turn.length) + 1)]
    offsets = [min([lane.centerline.distanceTo(turn.pointAlongBy(d)) for lane in egoWay]) for d in samples]
    mergeAlong = min([d for d, off in zip(samples, offsets) if off <= 1.75] + [turn.length])
    merge = turn.pointAlongBy(mergeAlong)
    mouth = turn.pointAlongBy(min([d for d, off in zip(samples, offsets) if off <= 3.6] + [mergeAlong]))
    mouthToMerge = distance from mouth to merge
    toMerge = (distance from self to route[0].centerline.end) + mergeAlong
    while egoFarFrom(ego, merge, timeToCover(toMerge, 0, turnSpeed), lead):
        take SetThrottleAction(0), SetBrakeAction(1)
    # stop at the mouth only if the ego has fallen behind since (ordered a step and a braking distance early)
    stopAt = 0.3 + turnSpeed * simulation().timestep + turnSpeed * turnSpeed / 16
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=turnSpeed) \
        until (distance from self to mouth) <= stopAt and (distance from self to merge) > mouthToMerge \
            and egoFarFrom(ego, merge, timeToCover(distance from self to merge, self.speed, turnSpeed), lead + 0.5)
    if (distance from self to mouth) <= stopAt + 1:
        while egoFarFrom(ego, merge, timeToCover(distance from self to merge, 0, turnSpeed), lead):
            take SetThrottleAction(0), SetBrakeAction(1)
        do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=turnSpeed)
    do FollowLaneBehavior(target_speed=speed)

behavior DriveRoute(speed, route):
    do FollowTrajectoryBehavior(target_speed=speed, trajectory=route, turn_speed=speed)
    do FollowLaneBehavior(target_speed=speed)

# 3. Road geometry: a four-way junction; the ego goes straight, the turner turns right from the
# side road into the lane the ego ends in
turnPairs = [(m, r) for junction in network.intersections for m in junction.maneuvers
             if m.type is ManeuverType.STRAIGHT
             for r in junction.maneuvers
             if r.type is ManeuverType.RIGHT_TURN and r.endLane is m.endLane]
turnPair = Uniform(*turnPairs)
egoManeuver = turnPair[0]
turnerManeuver = turnPair[1]
egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]
turnerRoute = [turnerManeuver.startLane, turnerManeuver.connectingLane, turnerManeuver.endLane]

# 4. Spawn positions
ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed,
    with route egoRoute,
    with behavior DriveRoute(globalParameters.ego_speed, egoRoute)
turner = new Car at turnerManeuver.startLane.centerline.pointAlongBy(-globalParameters.turner_wait_position),
    with name "turner",
    with speed 0,
    with behavior TurnInAheadOfEgo(globalParameters.turner_speed, turnerRoute,
                                   [egoManeuver.connectingLane, egoManeuver.endLane], globalParameters.entry_lead)
