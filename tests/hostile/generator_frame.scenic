# class: dunder-format
# caught-by: safety
# a generator's frame reaches globals without an underscore
param map = 'highway_straight'
model scenic.domains.driving.model
gen = (x for x in [1, 2])
gen.gi_frame.f_globals["__builtins__"]["open"]("/tmp/dv2s-hostile-marker", "w")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
