# class: param-path
# caught-by: safety
# the map's localPath leaving the script's folder with ..
param map = 'highway_straight'
param map = localPath('../../../../etc/passwd.xodr')
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
