# class: imports
# caught-by: safety
# import inside a monitor
param map = 'highway_straight'
model scenic.domains.driving.model
monitor Watch():
    from subprocess import run
    run(["touch", "/tmp/dv2s-hostile-marker"])
    wait
require monitor Watch()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
