param map = localPath('Town01.xodr')
param sumo_map = 'Town01.net.xml'
model scenic.simulators.metadrive.model

ego = new Car with behavior FollowLaneBehavior(target_speed=8)
other = new Car following roadDirection from ego for 20, with behavior FollowLaneBehavior(target_speed=6)
walker = new Pedestrian on visible sidewalk
