# class: imports
# caught-by: safety
# an import hidden in a requirement
param map = 'highway_straight'
model scenic.domains.driving.model
require __import__("os").system("touch /tmp/dv2s-hostile-marker") == 0

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
