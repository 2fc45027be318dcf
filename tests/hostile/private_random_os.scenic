# class: private-attribute
# caught-by: safety
# the issue's reproduction: os reached through random's private attribute
param map = 'highway_straight'
model scenic.domains.driving.model
import random
random._os.system("touch /tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
