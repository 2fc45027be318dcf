param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

behavior Track():
    take TrackWaypointsAction([self.position], cruising_speed=5)

ego = new Car
npc = new Car following roadDirection from ego for 15, with behavior Track()
