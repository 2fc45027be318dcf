# class: dunder-format
# caught-by: safety
# str.format walks attributes from a replacement field
param map = 'highway_straight'
model scenic.domains.driving.model
leak = "{0.__init__.__globals__}".format(Car)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
