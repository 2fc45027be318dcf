# class: dunder-format
# caught-by: safety
# a nested format spec walks attributes
param map = 'highway_straight'
model scenic.domains.driving.model
leak = "{0:{1.__class__}}".format(1, ego)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
