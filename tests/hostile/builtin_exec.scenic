# class: builtins
# caught-by: safety
# exec
param map = 'highway_straight'
model scenic.domains.driving.model
exec("open('/tmp/dv2s-hostile-marker', 'w').write('x')")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
