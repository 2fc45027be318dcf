# class: dunder-format
# caught-by: safety
# str.format called through the class
param map = 'highway_straight'
model scenic.domains.driving.model
leak = str.format("{0.__class__.__mro__}", ego)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
