# class: builtins
# caught-by: safety
# type, dir, vars, locals
param map = 'highway_straight'
model scenic.domains.driving.model
klass = type(ego)
names = dir(klass)
state = vars(ego)
local = locals()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
