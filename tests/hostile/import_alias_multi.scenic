# class: imports
# caught-by: safety
# aliased import hidden after an allowed one
param map = 'highway_straight'
model scenic.domains.driving.model
import math, subprocess as sp
sp.run(["touch", "/tmp/dv2s-hostile-marker"])

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
