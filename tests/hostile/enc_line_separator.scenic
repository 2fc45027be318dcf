# class: encoding
# caught-by: precheck
# U+2028 ends a line for editors but not for Python: a comment that is code
param map = 'highway_straight'
model scenic.domains.driving.model
# note ego_speed = 3

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
