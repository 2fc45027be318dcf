# class: dunder-format
# caught-by: safety
# a generator function's frame
param map = 'highway_straight'
model scenic.domains.driving.model
def numbers():
    yield 1
numbers().gi_frame.f_builtins["open"]("/tmp/dv2s-hostile-marker", "w")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
