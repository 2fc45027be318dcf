# class: dunder-format
# caught-by: safety
# mro() climbs to object
param map = 'highway_straight'
model scenic.domains.driving.model
base = Car.mro()[-1]

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
