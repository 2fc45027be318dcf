# class: resource-exhaustion
# caught-by: sandbox
# limit: iterations
# a requirement no sample satisfies
param map = 'highway_straight'
model scenic.domains.driving.model
gap = Range(0, 1)
require gap > 5

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
