# class: param-path
# caught-by: safety
# the map parameter read back through globalParameters, then its path methods
param map = 'highway_straight'
model scenic.domains.driving.model
here = globalParameters.map
moved = globalParameters['map']

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
