# class: dunder-format
# caught-by: safety
# format_map walks attributes and items
param map = 'highway_straight'
model scenic.domains.driving.model
leak = "{x.__init__.__globals__[os]}".format_map({"x": Car})

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
