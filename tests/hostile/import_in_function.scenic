# class: imports
# caught-by: safety
# import inside a function
param map = 'highway_straight'
model scenic.domains.driving.model
def helper():
    import shutil
    shutil.copy("/etc/hostname", "/tmp/dv2s-hostile-marker")
    return 1
x = helper()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
