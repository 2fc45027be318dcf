"""Benchmark scene: the ego and five cars following their lanes on a 4-lane highway."""

param map = 'highway_straight'
model scenic.domains.driving.model

param start = Range(200, 600)

def spot(ahead):
    """A point ``ahead`` metres past the ego's start, on a random lane."""
    return Uniform(*network.lanes).centerline.pointAlongBy(globalParameters.start + ahead)

ego = new Car at spot(0), with speed 25
car1 = new Car at spot(Range(15, 40)), with speed 24, with behavior FollowLaneBehavior(target_speed=24)
car2 = new Car at spot(Range(-40, -15)), with speed 26, with behavior FollowLaneBehavior(target_speed=26)
car3 = new Car at spot(Range(45, 70)), with speed 23, with behavior FollowLaneBehavior(target_speed=23)
car4 = new Car at spot(Range(75, 100)), with speed 22, with behavior FollowLaneBehavior(target_speed=22)
car5 = new Car at spot(Range(-70, -45)), with speed 27, with behavior FollowLaneBehavior(target_speed=27)
