param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

ego = new Car with speed 6
walker = new Pedestrian at (ego offset by (4.5 @ 25)), facing (ego.heading + 90 deg),
    with regionContainedIn everywhere,
    with behavior CrossingBehavior(ego, min_speed=1.5, threshold=40)
