# class: private-attribute
# caught-by: safety
# a module's loader imports any module
param map = 'highway_straight'
model scenic.domains.driving.model
import math
math.__loader__.load_module("os").system("touch /tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
