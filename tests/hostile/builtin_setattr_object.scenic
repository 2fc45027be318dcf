# class: builtins
# caught-by: safety
# setattr, object, breakpoint
param map = 'highway_straight'
model scenic.domains.driving.model
setattr(Car, "speed", 1)
hack = object
hook = breakpoint

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
