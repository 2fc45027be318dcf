# class: encoding
# caught-by: precheck
# a zero-width space inside a name: two names that look the same
param map = 'highway_straight'
model scenic.domains.driving.model
spe​ed = 3

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
