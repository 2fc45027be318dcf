param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

ego = new Car with visibleDistance 30, with viewAngle 60 deg
cone = new Cone visible
spot = new OrientedPoint on road
require ego can see cone
require not (ego can see spot)
