# class: param-path
# caught-by: safety
# the map's localPath as an absolute path
param map = 'highway_straight'
param map = localPath('/etc/ssl/private/road.xodr')
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
