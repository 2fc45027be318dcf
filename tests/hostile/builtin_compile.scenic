# class: builtins
# caught-by: safety
# compile
param map = 'highway_straight'
model scenic.domains.driving.model
code = compile("open('/tmp/dv2s-hostile-marker', 'w')", "<x>", "exec")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
