# class: encoding
# caught-by: precheck
# a lone carriage return ends a line for Python: the import hides in what readers see as a comment
param map = 'highway_straight'
model scenic.domains.driving.model
# harmless commentimport os

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
