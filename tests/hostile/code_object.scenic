# class: dunder-format
# caught-by: safety
# code objects
param map = 'highway_straight'
model scenic.domains.driving.model
probe = lambda: 0
code = probe.__code__.co_consts

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
