param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

ego = new Car with blueprint 'vehicle.lincoln.mkz_2017', with speed 8
box = new Barrier following roadDirection from ego for 14, facing roadDirection
