# class: param-path
# caught-by: safety
# localPath for a parameter the model never opens: a path object to move or overwrite any file
param map = 'highway_straight'
param target = localPath('/tmp/dv2s-hostile-marker')
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
