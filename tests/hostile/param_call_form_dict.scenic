# class: param-path
# caught-by: safety
# param called as a function bypasses the map-path rules
param map = 'highway_straight'
param({'map': localPath('/etc/shadow.xodr')})
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
