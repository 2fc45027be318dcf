# class: imports
# caught-by: safety
# import inside a behaviour
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Sneaky():
    import os
    os.system("touch /tmp/dv2s-hostile-marker")
    take SetThrottleAction(0.5)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior Sneaky()
