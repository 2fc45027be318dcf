# class: encoding
# caught-by: precheck
# bytes that are not UTF-8 (latin-1 look-alikes)
param map = 'highway_straight'
model scenic.domains.driving.model
spéed = 3

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
