# class: param-path
# caught-by: safety
# param called with keyword unpacking
param map = 'highway_straight'
options = {'target': localPath('/tmp/dv2s-hostile-marker')}
param(**options)
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
