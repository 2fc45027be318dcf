param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

ego = new Car with blueprint 'vehicle.tesla.model3', with rolename 'hero', with color Color(1, 0, 0),
    with behavior FollowLaneBehavior(target_speed=8)
lorry = new Car following roadDirection from ego for 25, with blueprint 'vehicle.carlamotors.firetruck'
cone = new Cone following roadDirection from ego for 12
bike = new Bicycle ahead of lorry by 10
walker = new Pedestrian on visible sidewalk
